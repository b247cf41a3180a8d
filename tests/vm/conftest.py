"""The ``vm`` marker and the fixtures of the tests that boot a throwaway qemu VM with SocketCAN
(tools/vcan-vm).

Select or drop them with ``-m vm`` / ``-m "not vm"``. They skip (never fail) when qemu, a kernel with
the CAN modules or busybox-static is missing, naming what is; ``sudo tools/vcan-vm --install --check``
installs those from Debian's packages. They fail, never hang, when the VM misbehaves: every VM has a
timeout, and once one failed to boot or timed out, the later tests fail at once with that failure
instead of each waiting out its own.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
VCAN_VM = ROOT / "tools" / "vcan-vm"
EXIT_MISSING, EXIT_TIMEOUT, EXIT_VM = 69, 124, 125


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "vm: boots a qemu VM with SocketCAN and vcan0 (tools/vcan-vm); slow under TCG")


class VmHealth:
    """The first VM failure (a boot failure or a timeout) of the session."""

    def __init__(self) -> None:
        self.failure: str | None = None

    def check(self) -> None:
        if self.failure is not None:
            pytest.fail(f"not run: a VM failed in an earlier test ({self.failure})")

    def failed(self, what: str, log: str) -> None:
        self.failure = self.failure or what
        pytest.fail(f"{what}:\n{log}")


@pytest.fixture(scope="session")
def _vm_dependencies() -> None:
    if not sys.platform.startswith("linux"):
        pytest.skip("tools/vcan-vm runs qemu on a Linux host")
    check = subprocess.run([sys.executable, str(VCAN_VM), "--check"], capture_output=True, text=True, timeout=120,
                           stdin=subprocess.DEVNULL)
    if check.returncode == EXIT_MISSING:
        pytest.skip("tools/vcan-vm cannot run here: " + " ".join(line for line in check.stderr.splitlines() if "missing" in line))
    assert check.returncode == 0, check.stdout + check.stderr


@pytest.fixture(scope="session")
def _vm_health() -> VmHealth:
    return VmHealth()


@pytest.fixture
def vm_ready(_vm_dependencies, _vm_health: VmHealth) -> VmHealth:
    """qemu, the kernel and busybox-static are there (else the test skips) and no VM failed yet (else
    it fails at once); the test reports a VM failure of its own with ``vm_ready.failed(...)``."""
    _vm_health.check()
    return _vm_health
