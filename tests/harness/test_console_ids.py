"""The console names each test by its id as the reports write it (``conformance/test_...``), from any directory
(issue #21): pytest alone prints ids relative to where it was started, e.g. ``../../<checkout>/conformance/...``."""

from __future__ import annotations

import json
import re
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

from procs import CKESC, env

import conformance


def test_ids_on_the_console_are_the_reports_ids_from_another_directory(tmp_path: Path) -> None:
    elsewhere = tmp_path / "a" / "b"
    elsewhere.mkdir(parents=True)
    done = subprocess.run([*CKESC, "run", "--verbose", "--reports", str(tmp_path / "reports"), "--trace-format", "none", "4.4.26",
                           "--emulator-faults", "esc_information_bcd_date"],
                          cwd=elsewhere, env=env(tmp_path), capture_output=True, text=True, timeout=120)
    assert done.returncode == 1, done.stdout[-2000:] + done.stderr[-2000:]
    results = tmp_path / "reports" / "latest" / "results.json"
    ids = [r["nodeid"] for r in json.loads(results.read_text())["results"]]
    assert ids and all(i.startswith("conformance/") for i in ids)
    for nodeid in ids:  # the progress line and pytest's short summary (--verbose), exactly as the reports name it
        assert f"{nodeid} FAILED" in done.stdout
        assert f"FAILED {nodeid}" in done.stdout
    assert "../" not in "".join(line for line in done.stdout.splitlines() if "::" in line)


#: one parametrised test of a small section, picked after collecting the whole suite (the path a whole run takes)
_ONE = "test_frames_are_29_bit_message_or_service_frames and provoked"
_ID = re.compile(r"[\w./-]+\.py::[^\s<>\"']+")


def _ids_of(reports: Path, console: str) -> dict[str, set[str]]:
    """The test ids each output of a run prints: the console, results.json, JUnit (its ``nodeid`` property) and
    report.html."""
    results = json.loads((reports / "results.json").read_text())["results"]
    junit = ET.parse(reports / "junit.xml").getroot()
    return {"console": set(_ID.findall(console)),
            "results.json": {r["nodeid"] for r in results},
            "junit.xml": {p.get("value") for p in junit.iter("property") if p.get("name") == "nodeid"},
            "report.html": set(_ID.findall((reports / "report.html").read_text()))}


def test_every_printed_id_selects_that_test_from_any_directory(tmp_path: Path) -> None:
    """Issue #29: installed where the path to site-packages goes through a symlink (a venv's lib64 -> lib), the
    whole suite's ids were relative to the package (``test_s4_1_framing.py::...``) and the console printed a path
    that does not exist (``.venv/lib/python3.11/site-packages/test_s4_1_framing.py::...``). Here the checkout is
    reached through a symlink; every id each output prints must be ``conformance/...`` and ``ckesc run ID`` must
    run exactly that test, from an unrelated directory."""
    link = tmp_path / "via-link"
    link.symlink_to(Path(conformance.__file__).resolve().parent.parent, target_is_directory=True)
    linked = dict(env(tmp_path), PYTHONPATH=str(link))
    first, second = tmp_path / "first", tmp_path / "second"
    first.mkdir(), second.mkdir()
    done = subprocess.run([*CKESC, "run", "--reports", str(tmp_path / "reports"), "--trace-format", "none", "--", "-k", _ONE],
                          cwd=first, env=linked, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout[-2000:] + done.stderr[-2000:]
    printed = _ids_of(tmp_path / "reports" / "latest", done.stdout)
    ids = printed["results.json"]
    assert len(ids) == 1 and next(iter(ids)).startswith("conformance/test_s4_1_framing.py::"), printed
    assert all(found == ids for found in printed.values()), printed
    nodeid = next(iter(ids))
    again = subprocess.run([*CKESC, "run", "--reports", str(tmp_path / "again"), "--trace-format", "none", nodeid],
                           cwd=second, env=linked, capture_output=True, text=True, timeout=120)
    assert again.returncode == 0, again.stdout[-2000:] + again.stderr[-2000:]
    ran = json.loads((tmp_path / "again" / "latest" / "results.json").read_text())["results"]
    assert [r["nodeid"] for r in ran] == [nodeid]
