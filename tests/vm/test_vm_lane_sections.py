"""tools/vm-lane's parts that need no VM: every entry of a named subset still selects tests (a renamed
test must not silently drop a SocketCAN path from CI), a wrong name is refused, and the power and bit
rate switches it gives ckesc run work against a running emulator (on python-can's virtual bus here)."""

from __future__ import annotations

import importlib.machinery
import importlib.util
import shlex
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from ckesc.emulator.control import control_request

ROOT = Path(__file__).resolve().parents[2]


def load_vm_lane():
    loader = importlib.machinery.SourceFileLoader("vm_lane", str(ROOT / "tools" / "vm-lane"))
    spec = importlib.util.spec_from_loader("vm_lane", loader)
    module = importlib.util.module_from_spec(spec)
    loader.exec_module(module)
    return module


vm_lane = load_vm_lane()


def collected(pytest_args: list[str]) -> list[str]:
    r = subprocess.run([sys.executable, "-m", "pytest", "--pyargs", "conformance", "-p", "no:cacheprovider", "--collect-only",
                        "-q", *pytest_args], cwd=ROOT, capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)
    assert r.returncode in (0, 5), r.stdout[-3000:] + r.stderr[-3000:]  # 5: nothing collected
    return [line for line in r.stdout.splitlines() if "::" in line]


def test_each_entry_of_the_ci_subset_selects_tests():
    tests = collected(vm_lane.selection("ci")[1])
    modules = vm_lane.section_modules()
    sections = [entry.partition("::")[0] for entry in vm_lane.SUBSETS["ci"]]
    assert len(set(sections)) == len(sections)  # one entry per section: a module's tests come from its entry
    for entry, section in zip(vm_lane.SUBSETS["ci"], sections):
        assert [t for t in tests if any(t.startswith(f"conformance/{m}.py::") for m in modules[section])], \
            f"{entry!r} selects no test"
    assert len(tests) > 40, tests


def test_the_ci_subset_power_cycles_only_where_that_covers_something_of_its_own():
    """Every power cycle waits for the boot and proves itself in a slow VM, on every CI run: the subset's
    power-cycle tests are chosen (persistence across a cycle, the bit rate move), not picked up with
    their section. A new one here is a decision: add it to the subset's entry, or leave it out."""
    ci = vm_lane.selection("ci")[1]
    assert collected([*ci, "-m", "power_cycle"]) == [
        "conformance/test_s4_4_19_set_baud.py::test_new_rate_only_after_the_next_power_up[code1-500000]",
        "conformance/test_s4_4_22_set_freq.py::test_intervals_persist_across_power_cycle",
    ]
    assert not [t for t in collected(ci) if "window" in t]  # the 120 s Set ID / Set Baud windows: minutes each


def test_all_selects_everything_and_unknown_names_are_refused():
    assert vm_lane.selection("all") == (["all"], [])
    with pytest.raises(SystemExit, match="no section or subset 'nonsense'; known: ci, all, 4.1"):
        vm_lane.selection("4.4.2,nonsense")


@pytest.fixture
def emulator(tmp_path):
    proc, port = vm_lane.start_emulator(sys.executable, tmp_path / "emulator.log", interface="virtual",
                                        channel=f"vm-lane-test-{tmp_path.name}", rt_priority=None)
    yield port
    proc.send_signal(signal.SIGTERM)
    proc.wait(30)


@pytest.mark.parametrize("bash", [True, False], ids=["bash", "ckesc-control"])
def test_switch_commands_power_and_move_the_emulator(emulator, bash, monkeypatch):
    if not bash:  # a machine without bash: `ckesc control`, slower, the same requests
        monkeypatch.setattr(vm_lane.shutil, "which", lambda name: None)
    elif vm_lane.shutil.which("bash") is None:
        pytest.skip("no bash here")

    def switch(line: str, ctl_args: str, bitrate: int | None = None) -> subprocess.CompletedProcess:
        cmd = vm_lane.switch_command(sys.executable, emulator, line, ctl_args)
        if bitrate is not None:  # as BusLane.reopen fills it in
            cmd = cmd.replace("{bitrate}", str(bitrate))
        return subprocess.run(shlex.split(cmd), capture_output=True, text=True, timeout=60, stdin=subprocess.DEVNULL)

    assert switch('{"cmd": "power", "action": "off"}', "power off").returncode == 0
    assert control_request(emulator, {"cmd": "status"})["powered"] is False
    assert switch('{"cmd": "power", "action": "on"}', "power on").returncode == 0
    assert switch('{"cmd": "bitrate", "bitrate": {bitrate}}', "bitrate {bitrate}", bitrate=250_000).returncode == 0
    status = control_request(emulator, {"cmd": "status"})
    assert (status["powered"], status["bitrate"]) == (True, 250_000)
    refused = switch('{"cmd": "power", "action": "sideways"}', "power sideways")
    assert refused.returncode != 0 and "sideways" in refused.stderr  # the refusal, not a silent pass
