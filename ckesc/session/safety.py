"""Zero throttle on the way out of a run that is being stopped (Ctrl-C, SIGTERM): the one place the session's
exit paths zero the DUT from outside a test's own :class:`~ckesc.bench.dut.Dut`."""

from __future__ import annotations

import pytest

from ..bench.link import Link
from .state import state

#: how long (lane time) the exit path reads the lane after its zero, so that the zero frames' echo is in the
#: test's trace before the trace closes: a few frames' time at the slowest legal bit rate
EXIT_READ_S = 0.01


def zero_throttle_now(config: pytest.Config, *, read_s: float = 0.0) -> None:
    """Stop every throttle stream on the run's lane (whichever host started it) and command zero on every
    channel; then read the lane for ``read_s`` so the zero frames are heard (traced). Best effort: nothing
    raises out of it (it runs on exit paths and in a signal handler)."""
    st = state(config)
    lane = st.lane
    if lane is None:
        return
    try:
        if st.profile is not None and st.node_id is not None:
            Link(lane, st.profile, node_id=st.node_id).zero_throttle()  # it stops the lane's streams first
        else:
            lane.stop_streams()
        end = lane.now() + read_s
        while read_s > 0 and (left := end - lane.now()) > 0:
            lane.recv(left)
    except Exception:  # noqa: BLE001 - best effort on the way out (BenchGone: the run says so already)
        pass

