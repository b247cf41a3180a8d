"""The ``vm`` marker: tests that boot a throwaway qemu VM with SocketCAN (tools/vcan-vm).

Select or drop them with ``-m vm`` / ``-m "not vm"``. They skip (never fail) when qemu, a kernel with
the CAN modules or busybox-static is missing; ``tools/vcan-vm --install --check`` (as root) installs
those from Debian's packages.
"""

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "vm: boots a qemu VM with SocketCAN and vcan0 (tools/vcan-vm); slow under TCG")
