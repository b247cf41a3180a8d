"""tools/vm-lane: the conformance suite over SocketCAN vcan0 inside a qemu VM, the emulator as the DUT.

One test, one VM: the CI subset (``tools/vm-lane --list-sections``), 2-5 minutes under TCG on a
2-core machine. It skips, with tools/vcan-vm's list of what is missing, when qemu, a kernel with the CAN
modules or busybox-static is not installed (``sudo tools/vcan-vm --install --check`` installs them).
The reports go to the checkout's reports/vm/<timestamp>/, as in any run of the lane (CI collects the
JUnit there; .gitignore keeps it out of git), the only directory the VM writes back. A run that
failed while the emulator was later than the profile's stated error (a host that starved the VM of CPU:
that run proves nothing either way) is repeated once, with a warning; any other failure fails at once.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ckesc.bench.profile import DutProfile

ROOT = Path(__file__).resolve().parents[2]
VM_LANE = ROOT / "tools" / "vm-lane"
PROFILE = ROOT / "ckesc" / "bench" / "profiles" / "vcan-vm.toml"
REPORTS = ROOT / "reports" / "vm"  # the inner run's JUnit lands in reports/vm/<timestamp>/ (kept out of git)
#: vm-lane's own --timeout, boot included: the ci subset took 2-5 minutes on a loaded 2-core host; never hang
LANE_TIMEOUT_S = 600
EXIT_TIMEOUT, EXIT_VM = 124, 125

pytestmark = [pytest.mark.vm, pytest.mark.realtime, pytest.mark.timeout(2 * (LANE_TIMEOUT_S + 90) + 60)]  # a second run when the first starved


def run_lane(vm) -> tuple[subprocess.CompletedProcess, list[Path]]:
    """tools/vm-lane (reports into the checkout's reports/vm/, where CI collects JUnit files), in its own
    session: should it outlive its own --timeout, the whole group (vcan-vm, and qemu, which dies with
    it) is killed, never left running. Returns what it did and the report directories it made."""
    REPORTS.mkdir(parents=True, exist_ok=True)
    before = set(REPORTS.iterdir())
    cmd = [sys.executable, str(VM_LANE), "--timeout", str(LANE_TIMEOUT_S), "--reports", str(REPORTS), "--quiet"]
    with subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                          stdin=subprocess.DEVNULL, start_new_session=True) as proc:
        try:
            out, err = proc.communicate(timeout=LANE_TIMEOUT_S + 60)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            vm.failed(f"tools/vm-lane did not stop after its own --timeout {LANE_TIMEOUT_S} s; killed", err[-6000:])
    if proc.returncode in (EXIT_TIMEOUT, EXIT_VM):
        vm.failed(f"the VM itself failed (tools/vm-lane exit {proc.returncode})", err[-6000:])
    made = sorted(d for d in set(REPORTS.iterdir()) - before if d.is_dir() and not d.is_symlink())
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err), made


def lane_record(made: list[Path]) -> dict:
    found = [d / "vm-lane.json" for d in made if (d / "vm-lane.json").exists()]
    return json.loads(found[-1].read_text()) if found else {}


def failure(r: subprocess.CompletedProcess, made: list[Path]) -> str:
    why = lane_record(made)
    late = ""
    if why.get("late_within_error") is False:
        late = (f"\nthe emulator was {why['emulator_late_max_s'] * 1000:.0f} ms late at worst, beyond the profile's "
                f"{why['profile_error_s'] * 1000:.0f} ms: the host starved the VM of CPU")
    summary = [d / "summary.txt" for d in made if (d / "summary.txt").exists()]
    return (f"exit {r.returncode}{late}; reports: {', '.join(map(str, made)) or 'none'}"
            f"\n--- summary\n{summary[-1].read_text() if summary else '(none)'}"
            f"\n--- stdout\n{r.stdout[-6000:]}\n--- stderr\n{r.stderr[-4000:]}")


def test_ci_subset_passes_and_writes_junit(vm_ready):
    r, made = run_lane(vm_ready)
    if r.returncode != 0 and lane_record(made).get("late_within_error") is False:
        # The profile's stated error assumes the emulator is never later than it; a host that starved the VM
        # of CPU broke that premise, and this run's verdicts prove nothing either way. Once more, and said so.
        warnings.warn(f"VM lane run 1 of 2 failed on a starved host; running again:\n{failure(r, made)[:3000]}", stacklevel=1)
        r, made = run_lane(vm_ready)
    assert r.returncode == 0, failure(r, made)

    assert len(made) == 1, f"expected one new <timestamp>/ report directory under {REPORTS}: {made}"
    run = made[0]
    assert run.parent == REPORTS and (REPORTS / "latest").resolve() == run.resolve()
    junit = ET.parse(run / "junit.xml").getroot()
    suites = junit.findall("testsuite") if junit.tag == "testsuites" else [junit]
    cases = [c for s in suites for c in s.findall("testcase")]
    assert cases, "the JUnit report has no test case"
    assert not [c for c in cases if c.find("failure") is not None or c.find("error") is not None]

    # it really ran on SocketCAN inside the VM, against the emulator, with power switched through its control channel
    lane = json.loads((run / "vm-lane.json").read_text())
    assert lane["in_vm"] is True and lane["exit"] == 0 and lane["sections"] == "ci"
    results = json.loads((run / "results.json").read_text())
    info = results["info"]
    assert (info["dut"], info["lane"], info["clock"], info["power"]) == ("bus", "bus", "bus timestamp", "command")
    # the profile's stated timing error is in every report
    error_s = DutProfile.load(str(PROFILE)).error_s
    assert info["timing_error_s"] == lane["profile_error_s"] == error_s > 0
    assert f"stated error +-{error_s * 1000:g} ms" in (run / "summary.txt").read_text()
    assert {p.get("value") for s in suites for p in s.iter("property") if p.get("name") == "timing_error_s"} == {str(error_s)}
    outcomes = {r["nodeid"]: r["outcome"] for r in results["results"]}
    # persistence across a power cycle (functional: never relaxed on this lane) and the bit rate hook were judged
    assert [o for n, o in outcomes.items() if "intervals_persist_across_power_cycle" in n] == ["PASS"]
    assert [o for n, o in outcomes.items() if "new_rate_only_after_the_next_power_up" in n] == ["PASS"]
    # an INCONCLUSIVE result says why
    for res in results["results"]:
        if res["outcome"] == "INCONCLUSIVE":
            assert "INCONCLUSIVE: " in res["message"] and len(res["message"]) > len("INCONCLUSIVE: "), res
    status = json.loads((run / "emulator-stats.json").read_text())  # `ckesc control status` after the run
    assert status["lateness"]["count"] > 0 and status["escs"][0]["power_ups"] > 1
