"""Record the faultless simulated run whose figures the documentation cites (``faultless-run.json`` beside this file).

The pages never write a test count, a verdict count or the run's protocol time by hand: the ``{ckesc-figure}`` role
(``docs/_ext/ckesc_docs.py``) reads them from this record, and the docs build fails when the record is not of the
suite the code has now (its test ids differ from what pytest collects). After adding, removing or renaming a
conformance test, re-record it::

    python docs/recorded/record_run.py                # the whole suite in the simulated lane (10-60 s)
    python docs/recorded/record_run.py --from reports/latest/results.json   # a complete faultless simulated run's record

A record is only made of a complete run in the simulated lane without faults or variants, in the default run order.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
RECORD = Path(__file__).with_name("faultless-run.json")
COMMAND = ["ckesc", "run", "--lane", "simulated", "-q"]


def ids_digest(ids: list[str]) -> str:
    """One fingerprint of a set of test ids (order does not matter): what the docs build compares with collection."""
    return hashlib.sha256("\n".join(sorted(ids)).encode()).hexdigest()[:16]


def summary(doc: dict, wall_s: float | None) -> dict:
    """The record of one run's results.json; SystemExit if the run is not a complete faultless simulated one."""
    info = doc.get("info", {})
    if (info.get("lane") != "simulated" or info.get("faults") or info.get("emulator_variants") not in (None, "", "defaults")
            or not info.get("complete")):
        raise SystemExit("a record is made from a complete, faultless run in the simulated lane: "
                         f"lane={info.get('lane')} faults={info.get('faults')} variants={info.get('emulator_variants')} "
                         f"complete={info.get('complete')}")
    ids = [r["nodeid"] for r in doc["results"]]
    verdicts: dict[str, int] = {}
    for r in doc["results"]:
        verdicts[r["outcome"]] = verdicts.get(r["outcome"], 0) + 1
    return {
        "about": "the faultless simulated run the documentation's figures come from (docs/recorded/record_run.py)",
        "recorded": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d"),
        "command": " ".join(COMMAND),
        "suite_version": info.get("suite_version"),
        "git_revision": info.get("git_revision"),
        "python": sys.version.split()[0],
        "tests": len(ids),
        "test_ids_sha256": ids_digest(ids),
        "verdicts": dict(sorted(verdicts.items())),
        "protocol_s": round(float(info["lane_seconds"]), 1),
        "wall_s": None if wall_s is None else round(wall_s, 1),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--from", dest="results", type=Path, help="an existing run's results.json instead of a new run")
    ap.add_argument("--out", type=Path, default=RECORD)
    args = ap.parse_args()
    if args.results is not None:
        record = summary(json.loads(args.results.read_text(encoding="utf-8")), None)
    else:
        with tempfile.TemporaryDirectory(prefix="ckesc-record-") as tmp:
            t0 = time.perf_counter()
            done = subprocess.run([sys.executable, "-m", "ckesc", *COMMAND[1:], "--reports", tmp], cwd=ROOT,
                                  capture_output=True, text=True)
            wall = time.perf_counter() - t0
            reports = sorted(Path(tmp).glob("2*/results.json"))
            if done.returncode != 0 or not reports:
                raise SystemExit(f"{' '.join(COMMAND)} exited {done.returncode}:\n{done.stdout[-3000:]}{done.stderr[-2000:]}")
            record = summary(json.loads(reports[-1].read_text(encoding="utf-8")), wall)
    args.out.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    print(f"{args.out}: {record['tests']} tests, {record['verdicts']}, {record['protocol_s']} s of protocol time")


if __name__ == "__main__":
    main()
