"""The console names each test by its id as the reports write it (``conformance/test_...``), from any directory
(issue #21): pytest alone prints ids relative to where it was started, e.g. ``../../<checkout>/conformance/...``."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

from procs import CKESC, env


def test_ids_on_the_console_are_the_reports_ids_from_another_directory(tmp_path: Path) -> None:
    elsewhere = tmp_path / "a" / "b"
    elsewhere.mkdir(parents=True)
    done = subprocess.run([*CKESC, "run", "--reports", str(tmp_path / "reports"), "--trace-format", "none", "4.4.26",
                           "--emulator-faults", "esc_information_bcd_date"],
                          cwd=elsewhere, env=env(tmp_path), capture_output=True, text=True, timeout=120)
    assert done.returncode == 1, done.stdout[-2000:] + done.stderr[-2000:]
    results = tmp_path / "reports" / "latest" / "results.json"
    ids = [r["nodeid"] for r in json.loads(results.read_text())["results"]]
    assert ids and all(i.startswith("conformance/") for i in ids)
    for nodeid in ids:  # the progress line and pytest's short summary, exactly as the reports name it
        assert f"{nodeid} FAILED" in done.stdout
        assert f"FAILED {nodeid}" in done.stdout
    assert "../" not in "".join(line for line in done.stdout.splitlines() if "::" in line)
