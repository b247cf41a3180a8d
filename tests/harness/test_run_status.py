"""The run's status, decided once at the session's end from its typed results (issue #35, item 3).

A test the run did not finish is never a PASS: ``ckesc run`` interrupted while a test runs keeps its report and exits
130, and the test the interrupt cut is "not run to its end", never counted as PASS.

Tried as a user meets it: a real ``ckesc run`` process (the simulated lane), a real SIGINT to its process group. To
land the signal inside a test's call phase every time (a user's Ctrl-C after 5 s did, by chance), a small pytest
plugin handed to the run after ``--`` says on the console when the chosen test's call begins and waits there for the
signal; the signal, the run's guard and pytest's unwinding are the real ones."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
from pathlib import Path

from procs import CKESC, end
from procs import env as _env

CUT = "conformance/test_s4_4_20_set_led.py::test_not_set_while_reporting_is_suspended[no-save]"
MARK = "ckesc-test: the call phase is under way"

#: the plugin that holds the chosen test's call phase until the signal comes
CUTTER = f'''
import signal
import pytest

@pytest.hookimpl(tryfirst=True)
def pytest_runtest_call(item):
    if item.nodeid == {CUT!r}:
        with item.config.pluginmanager.getplugin("capturemanager").global_and_fixture_disabled():
            print({MARK!r}, flush=True)
        signal.pause()
'''


def _lines_until(proc: subprocess.Popen, says: str):
    """The process's output, line by line, up to the first line that contains ``says``."""
    assert proc.stdout is not None
    for line in proc.stdout:
        yield line
        if says in line:
            return


def test_the_test_an_interrupt_cuts_is_not_run_to_its_end_never_a_pass(tmp_path: Path):
    (tmp_path / "cutter.py").write_text(CUTTER, encoding="utf-8")
    env = dict(_env(tmp_path), PYTHONPATH=os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([*CKESC, "run", "-q", "--reports", str(tmp_path / "reports"), "4.4.20", "--", "-p", "cutter"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    try:
        out = list(_lines_until(proc, MARK))
        os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C at a terminal: the foreground process group
        rest, _ = proc.communicate(timeout=120)
    finally:
        end(proc)
    text = "".join(out) + rest
    assert MARK in text and proc.returncode == 130, text[-3000:]
    doc = json.loads((tmp_path / "reports" / "latest" / "results.json").read_text(encoding="utf-8"))
    assert doc["info"]["incomplete"].startswith("interrupted"), doc["info"]
    verdicts = {r["nodeid"]: r["outcome"] for r in doc["results"]}
    assert CUT not in verdicts, f"the cut test has a verdict: {verdicts.get(CUT)}"
    cut = [n for n in doc["not_run"] if n["nodeid"] == CUT]
    assert cut and "interrupted" in cut[0]["reason"], doc["not_run"]
    # one story: pytest's closing line counts the PASSes results.json and summary.txt count
    closing = text.strip().splitlines()[-1]
    counts = {m.group(2): int(m.group(1)) for m in re.finditer(r"(\d+) (\w+)", closing)}
    assert counts.get("passed", 0) == list(verdicts.values()).count("PASS") > 0, (closing, verdicts)
    summary = (tmp_path / "reports" / "latest" / "summary.txt").read_text(encoding="utf-8")
    assert summary.startswith("INTERRUPTED"), summary[:300]


def test_a_session_that_runs_no_test_is_no_failure(tmp_path: Path):
    """The session's end decides the run's status (ckesc.reporting.exits.of_run) from the results it has: a collection
    (``--collect-only``, as the docs' build collects the suite's ids) has none, and fails nothing."""
    done = subprocess.run([*CKESC[:1], "-m", "pytest", "--pyargs", "conformance", "-p", "no:cacheprovider", "--collect-only",
                           "-q"], cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and "tests collected" in done.stdout, done.stdout[-2000:] + done.stderr[-2000:]


def test_strict_fails_the_run_on_an_inconclusive_result(tmp_path: Path):
    """``--strict`` (the plugin's ``--ckesc-strict``) is read where the status is decided: an INCONCLUSIVE result (an
    ESC that sends no MSG_EXP9, which R9-exp leaves open) fails the run with it, and only with it."""
    codes = []
    for strict in ([], ["--strict"]):
        done = subprocess.run([*CKESC, "run", "-q", *strict, "--reports", str(tmp_path / "reports"), "--emulator-option",
                               "exp_frames=exp1_only", "4.4.11"], cwd=tmp_path, env=_env(tmp_path), capture_output=True,
                              text=True, timeout=300)
        assert done.stdout.strip().splitlines()[-1].startswith("1 inconclusive"), done.stdout[-2000:] + done.stderr
        codes.append(done.returncode)
    assert codes == [0, 1]
