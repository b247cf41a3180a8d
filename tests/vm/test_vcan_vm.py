"""tools/vcan-vm: a command runs in a qemu VM whose kernel has SocketCAN, with vcan0 up.

Each test boots a VM (about 5-10 s under TCG, more on a loaded machine) unless it only checks the
dependency report. The tests skip, with the tool's own list of what is missing, when qemu, the kernel
or busybox-static is not installed; ``sudo tools/vcan-vm --install --check`` installs them.
The Python inside the VM is this test run's own interpreter (its venv lives on the host's root,
which the VM mounts over 9p), so python-can is the one under test.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "vcan-vm"
VM_TIMEOUT = 240  # the tool's own --timeout: each VM here is up in ~10 s and done in well under a minute, never hang

EXIT_MISSING, EXIT_TIMEOUT, EXIT_VM = 69, 124, 125

pytestmark = [pytest.mark.vm, pytest.mark.realtime, pytest.mark.timeout(VM_TIMEOUT + 180)]


def vcan_vm(*args: str, cwd: Path = ROOT, timeout: float = VM_TIMEOUT + 60) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(TOOL), *args], cwd=cwd, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL
    )


def run_in_vm(vm, *cmd: str, opts: tuple[str, ...] = ("--read-only",), cwd: Path = ROOT) -> subprocess.CompletedProcess:
    r = vcan_vm("--timeout", str(VM_TIMEOUT), *opts, "--", *cmd, cwd=cwd)
    if r.returncode in (EXIT_TIMEOUT, EXIT_VM):
        vm.failed(f"the VM itself failed (tools/vcan-vm exit {r.returncode})", r.stderr)
    return r


def test_af_can_raw_socket_binds_vcan0(vm_ready):
    code = (
        "import socket; s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW); "
        "s.bind(('vcan0',)); print('ok')"
    )
    r = run_in_vm(vm_ready, sys.executable, "-c", code)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "ok"


def test_python_can_round_trip_on_vcan0(vm_ready):
    code = (
        "import can\n"
        "a = can.Bus(interface='socketcan', channel='vcan0', receive_own_messages=True)\n"
        "b = can.Bus(interface='socketcan', channel='vcan0')\n"
        "a.send(can.Message(arbitration_id=0x123, data=[1], is_extended_id=True))\n"
        "own, other = a.recv(5), b.recv(5)\n"
        "for m in (own, other):\n"
        "    print(m.channel, hex(m.arbitration_id), m.is_extended_id, m.data.hex())\n"
        "a.shutdown(); b.shutdown()\n"
    )
    r = run_in_vm(vm_ready, sys.executable, "-c", code)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == ["vcan0 0x123 True 01", "vcan0 0x123 True 01"], r.stdout + r.stderr


def test_bus_lane_on_vcan0_stamps_echoes_and_reopens(vm_ready):
    """The harness's BusLane on real SocketCAN: a receive buffer for a stalled host, the host's frame
    back as its receive_own_messages echo with a kernel stamp, a reopen through the bit rate command."""
    code = (
        "import sys, can\n"
        "from ckesc.bench.lanes import BusLane, SOCKETCAN_RCVBUF\n"
        "from ckesc.bench.power import NoPower\n"
        "lane = BusLane({'interface': 'socketcan', 'channel': 'vcan0'}, NoPower(), timing_error=0.0, bitrate_cmd='true')\n"
        "assert lane.rcvbuf >= SOCKETCAN_RCVBUF, lane.rcvbuf\n"
        "for rate in (500000, 1000000):\n"
        "    lane.reopen(rate)\n"
        "    lane.bus.send(can.Message(arbitration_id=0x1F4E5200, data=b'\\xc0', is_extended_id=True))\n"
        "    echo = lane.recv(5)\n"
        "    assert echo is not None and not echo.is_rx and 0 < echo.timestamp <= lane.now(), echo\n"
        "    print(lane.bitrate, hex(echo.arbitration_id))\n"
        "lane.close()\n"
    )
    r = run_in_vm(vm_ready, sys.executable, "-c", code)
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines() == ["500000 0x1f4e5200", "1000000 0x1f4e5200"], r.stdout + r.stderr


def test_exit_status_and_streams_pass_through(vm_ready):
    r = run_in_vm(vm_ready, "sh", "-c", "echo out; echo err >&2; exit 7")
    assert r.returncode == 7, r.stderr
    assert r.stdout == "out\n"
    assert "err\n" in r.stderr
    assert "@@vcan-vm" not in r.stdout + r.stderr


def test_cwd_env_and_read_write_share(vm_ready, tmp_path):
    script = 'printf "%s %s %s\\n" "$PWD" "$VCAN_VM" "$CKESC_VM_PROBE" > out.txt; ip -o link show vcan0 >> out.txt'
    r = run_in_vm(vm_ready, "sh", "-c", script, opts=("--share-rw", str(tmp_path), "--env", "CKESC_VM_PROBE=42"), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    lines = (tmp_path / "out.txt").read_text().splitlines()
    assert lines[0] == f"{os.path.realpath(tmp_path)} 1 42"
    assert "vcan0" in lines[1] and "UP" in lines[1]


def test_missing_kernel_is_reported_not_run(tmp_path):
    r = vcan_vm("--kernel", "0.0-no-such-kernel", "--result-file", str(tmp_path / "result"), "--", "true", timeout=120)
    assert r.returncode == EXIT_MISSING, r.stderr
    assert "linux-image-amd64" in r.stderr
    assert (tmp_path / "result").read_text().strip() == "missing-dependency"


def test_timeout_kills_the_vm(vm_ready, tmp_path):
    t0 = time.monotonic()
    r = vcan_vm("--timeout", "3", "--read-only", "--result-file", str(tmp_path / "result"), "--", "sleep", "600")
    assert r.returncode == EXIT_TIMEOUT, r.stderr
    assert (tmp_path / "result").read_text().strip() == "timeout"
    assert time.monotonic() - t0 < 60


def test_vm_failure_is_125_with_the_console_log(vm_ready, tmp_path):
    # a 9p message size the kernel refuses: the init cannot mount its control share and powers off
    r = vcan_vm("--msize", "512", "--read-only", "--result-file", str(tmp_path / "result"), "--", "true")
    assert r.returncode == EXIT_VM, r.stderr
    assert "failed to boot" in r.stderr and "VM console" in r.stderr
    assert (tmp_path / "result").read_text().strip() == "vm-failure"
