"""One verdict decision from typed outcomes (issue #28, item 3): INCONCLUSIVE is what an
:class:`~ckesc.bench.outcomes.Inconclusive` (or a measurement inside the bench's error) ends a test with, SKIPPED
any other skip, whatever words their messages use. Tried in a real pytest process against the emulator. (A test
citing an unknown requirement id stops the run at collection: ``ckesc.session.collection``; every id the suites cite
is checked statically in test_requirements.py.)"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

_SUITE = '''
import pytest

from ckesc.bench.outcomes import Inconclusive

SECTION = "4.4.2"


class Unworded(Inconclusive):
    """An Inconclusive whose message does not say the word."""

    def __init__(self, msg):
        pytest.skip.Exception.__init__(self, msg=msg, allow_module_level=False)


@pytest.mark.requirement("4.4.2-4")
def test_measured_inside_the_error(dut):
    dut.record.measure("answer delay", 63.9, limit=64, unit="ms", error=0.5, requirement="4.4.2-4")


@pytest.mark.requirement("4.4.2-4")
def test_inconclusive_not_saying_so(dut):
    raise Unworded("the power cycle was not proven")


@pytest.mark.requirement("4.4.2-4")
def test_skip_saying_inconclusive(dut):
    pytest.skip("INCONCLUSIVE is only a word here: this is a plain skip")
'''

def _run(tmp_path: Path, suite: str) -> subprocess.CompletedProcess:
    """Run ``suite`` as the conformance module of a fresh directory, against the emulator."""
    (tmp_path / "conformance").mkdir()
    (tmp_path / "conformance" / "__init__.py").write_text("")
    (tmp_path / "conformance" / "test_outcomes.py").write_text(suite)
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", "--rootdir", str(tmp_path),
                           "conformance/test_outcomes.py", "--ckesc-reports", "reports"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=300)


def test_inconclusive_is_decided_by_its_type_not_its_message(tmp_path):
    _run(tmp_path, _SUITE)
    run = next(p for p in (tmp_path / "reports").iterdir() if p.is_dir() and not p.is_symlink())
    res = {r["name"]: r for r in json.loads((run / "results.json").read_text())["results"]}
    assert res["test_measured_inside_the_error"]["outcome"] == "INCONCLUSIVE", res["test_measured_inside_the_error"]
    assert res["test_inconclusive_not_saying_so"]["outcome"] == "INCONCLUSIVE", res["test_inconclusive_not_saying_so"]
    assert res["test_inconclusive_not_saying_so"]["message"] == "the power cycle was not proven"
    assert res["test_skip_saying_inconclusive"]["outcome"] == "SKIPPED", res["test_skip_saying_inconclusive"]
