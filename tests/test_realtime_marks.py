"""Every test module that starts a real-time DUT carries the ``realtime`` mark (tests/conftest.py): under
``-n auto`` an unmarked one would run beside another real-time test and each would judge the other's load."""

from __future__ import annotations

import re
from pathlib import Path

TESTS = Path(__file__).resolve().parent
#: what starts a DUT or a bench that keeps wall-clock time: `ckesc emulate` (procs.Emulator), the clean-room ESC,
#: the real-time lanes, a soak in real time, the VM
REAL_TIME = re.compile(r"\bEmulator\(|\bCleanRoom\(|RealtimeEmulatorLane\(|[\"']realtime[\"']|--lane[\"'], [\"']realtime|vm_ready")

#: modules that name the real-time lane without running it
NAMED_ONLY = {"soak/test_soak_rig.py": "`--lane realtime` only as an option a rig batch refuses",
              "harness/test_rig.py": "a rig file's bench with `lane = \"realtime\"`, read, never run"}


def test_modules_that_start_a_real_time_dut_are_marked():
    unmarked = [str(p.relative_to(TESTS)) for p in sorted(TESTS.rglob("test_*.py"))
                if REAL_TIME.search(text := p.read_text(encoding="utf-8")) and "pytest.mark.realtime" not in text and str(p.relative_to(TESTS)) not in NAMED_ONLY]
    assert not unmarked, f"mark them `pytestmark = pytest.mark.realtime` (or the real-time tests in them): {unmarked}"


def test_xdist_keeps_a_group_on_one_worker(pytester):
    """The grouping README's command relies on, against the installed pytest and pytest-xdist (pytest 9.2 with
    pytest-xdist 3.8 drops it silently: pytest-xdist#1386, hence the pin in pyproject's test extra)."""
    pytester.makeconftest((TESTS / "conftest.py").read_text(encoding="utf-8"))
    pytester.makeini("[pytest]\nmarkers =\n    realtime: times real processes")
    pytester.makepyfile(test_rt="import pytest\npytestmark = pytest.mark.realtime\n"
                                "@pytest.mark.parametrize('i', range(6))\ndef test_rt(i): pass\n",
                        test_sim="import pytest\n@pytest.mark.parametrize('i', range(6))\ndef test_sim(i): pass\n")
    result = pytester.runpytest_subprocess("-n", "2", "--dist", "loadgroup", "-v", "-p", "no:randomly", "-p", "no:labgrid",
                                           "-p", "no:cacheprovider")
    workers = {m.group(1) for m in re.finditer(r"\[(gw\d)\] .*PASSED test_rt\.py", result.stdout.str())}
    assert result.ret == 0 and len(workers) == 1, result.stdout.str()
