"""What one test's traffic shows about timing, for the report's plots: answer delays, report intervals and
R8's comm-loss timeline, from the bus rules' own tracker (:mod:`.tracker`) run over the test's frames, so
that a plot draws the numbers a verdict judged (the same pairing of answers with requests, the same
interval targets and restarts). Sans-IO.
"""

from __future__ import annotations

from typing import Any

from ..protocol.ids import HOST_NODE_ID
from .rules import BusRules
from .tracker import TimingEvidence


def heard(frames: list, *, host: int, node: int | None, tolerance: float = 0.0) -> TimingEvidence:
    """What the tracker pairs over ``frames`` (decoded, in order, with their bus timestamps: ``Dut.trace``):
    ``host``'s frames are the host's own (their echo); intervals and MSG1 of ``node`` only."""
    rules = BusRules(tolerance=tolerance, complete=True, power_known=True, host_nodes={HOST_NODE_ID, host})
    rules.heard = TimingEvidence(node=node)
    for f in frames:
        if f.timestamp is not None:
            rules.feed(f.can_id, f.data, f.timestamp, own=f.source == host)
    return rules.heard


def evidence(frames: list, *, host: int, node: int | None, comm_loss: bool = False) -> dict[str, Any]:
    """A test's ``evidence`` in results.json (:class:`~.tracker.TimingEvidence`'s fields; with ``comm_loss``, R8's
    timeline): what :func:`heard` pairs over its frames."""
    return heard(frames, host=host, node=node).to_json(comm_loss=comm_loss)
