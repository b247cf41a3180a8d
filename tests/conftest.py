"""The project's own tests run in parallel (README: ``python -m pytest -n auto --dist loadgroup``), except the ones
that time a real process against the wall clock.

Those carry the ``realtime`` mark (a module's ``pytestmark`` or a test's own) and are put in one xdist group, so
one worker runs them one after another while the others run the simulated lane's tests. Two real-time tests at
once would each be the other's load: the emulator's and the clean-room ESC's timers would wake late and a test
would judge the machine, not the DUT. The VM's tests (mark ``vm``) are a group of their own: the VM keeps its own
time inside qemu, and they run beside the real-time group rather than after it, which would make the two groups
together longer than all the simulated tests. Without ``-n`` nothing changes: every test runs in one process, in
order.
"""

from __future__ import annotations

import pytest


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist's worker reads the groups (it appends "@group" to the node ids)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.get_closest_marker("vm") is not None:
            item.add_marker(pytest.mark.xdist_group("vm"))
        elif item.get_closest_marker("realtime") is not None:
            item.add_marker(pytest.mark.xdist_group("realtime"))
