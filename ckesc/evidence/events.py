"""What the bus reader (:class:`~.rules.BusRules` over :mod:`.tracker`) tells a consumer as it reads, typed, one call
per event, sans-IO: the state it keeps for its own stateful rules, handed out instead of being kept again.

    class Mine(ReaderEvents):
        def reset(self, ts, node, sign, signs): ...     # override what you consume; the rest stay no-ops
    rules = BusRules(...); rules.events = Mine()

Every call comes from inside :meth:`~.rules.BusRules.feed`, for the frame being fed, in the order the reader decides
(a reset's sign before the report that shows it). ``ts`` is that frame's lane timestamp (its end on the bus), ``node``
the node it concerns. The reader judges; a consumer only keeps what it alone needs of these (the soak: its minute
trend, its histograms, its statement), and judges with the reader's rules or the judgement functions, never its own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ..protocol.judgements import Reset
    from .pairing import ReplyPairing
    from .resets import ResetSigns


class ReaderEvents:
    """The events, each a no-op here (a consumer overrides those it takes)."""

    def query(self, ts: float, source: int) -> None:
        """A GET_ESC_ID query from node ``source`` (the host's, a flight controller's), as the pairing took it."""

    def reply(self, ts: float, node: int, pairing: ReplyPairing, can_id: int, data: bytes) -> None:
        """A GET_ESC_ID reply from ESC ``node``: which query it answers (:class:`~.pairing.QueryPairing`'s word)."""

    def report(self, ts: float, node: int, name: str, restarted: bool) -> None:
        """A periodic report (MSG1..3, CAN Test's) of ESC ``node``; ``restarted``: its transfer id started again after
        a gap (the first report after a restart, R9a: :func:`~ckesc.protocol.judgements.r19_counter_restarted`)."""

    def reset(self, ts: float, node: int, sign: Reset, signs: ResetSigns) -> None:
        """A sign of a reset of ESC ``node`` (R19, R17): ``signs.same`` says whether it shows one already counted,
        ``signs.since`` when the reset began at the latest. Comes before the report (:meth:`report`) that shows it."""

    def counter(self, ts: float, node: int, name: str, value: int) -> None:
        """A 241 answer of ESC ``node`` read as counter ``name`` (``power_ups``, ``run_time``), before it is judged."""

    def msg1(self, ts: float, node: int, flag: bool, last_command: float | None) -> None:
        """An MSG1 of ESC ``node``: its comm-loss flag (R8), and when the last throttle command was on the bus (None:
        none yet)."""
