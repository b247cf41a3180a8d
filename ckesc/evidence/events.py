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
    from .pairing import ReplyPairing, ResponsePairing
    from .resets import ResetSigns


class ReaderEvents:
    """The events, each a no-op here (a consumer overrides those it takes)."""

    #: :meth:`command` is told (it comes for a stream's every frame: only a consumer that keeps them asks for it)
    wants_commands = False

    def query(self, ts: float, source: int) -> None:
        """A GET_ESC_ID query from node ``source`` (the host's, a flight controller's), as the pairing took it."""

    def reply(self, ts: float, node: int, pairing: ReplyPairing, can_id: int, data: bytes) -> None:
        """A GET_ESC_ID reply from ESC ``node``: which query it answers (:class:`~.pairing.QueryPairing`'s word)."""

    def response(self, ts: float, node: int, pairing: ResponsePairing, can_id: int, data: bytes) -> None:
        """An answer of ESC ``node`` to a request (a service response) or to a broadcast command (MSG Control's
        answer): which request it answers, F4's pairing (:class:`~.pairing.RequestPairing`'s word), before it is
        judged."""

    def report(self, ts: float, node: int, name: str, restarted: bool) -> None:
        """A periodic report (MSG1..3, CAN Test's) of ESC ``node``; ``restarted``: its transfer id started again after
        a gap (the first report after a restart, R9a: :func:`~ckesc.protocol.judgements.r19_counter_restarted`)."""

    def reset(self, ts: float, node: int, sign: Reset, signs: ResetSigns) -> None:
        """A sign of a reset of ESC ``node`` (R19, R17): ``signs.same`` says whether it shows one already counted,
        ``signs.since`` when the reset began at the latest. Comes before the report (:meth:`report`) that shows it."""

    def counter(self, ts: float, node: int, name: str, value: int) -> None:
        """A 241 answer of ESC ``node`` read as counter ``name`` (``power_ups``, ``run_time``), before it is judged."""

    def msg1(self, ts: float, node: int, flag: bool, last_command: float | None) -> None:
        """An MSG1 of ESC ``node``: its comm-loss flag (R8), and when the last throttle command that addresses the
        node's throttle channel was on the bus (R8's clock, :mod:`.commands`; None: none yet, or the node's channel is
        not known)."""

    def command(self, ts: float, node: int) -> None:
        """A throttle command that addresses ESC ``node``'s throttle channel (as the reader knows it, :mod:`.commands`):
        told only where :attr:`wants_commands`."""


class EventLog(ReaderEvents):
    """A consumer that keeps what the reader told of one bounded stretch of the bus (a program of ``ckesc explore``,
    a test's trace), for a judge that reads it after the stretch: which request each answer answers (F4), which query
    each GET_ESC_ID reply answers, each report with its restart, each MSG1's comm flag with the last command, each
    command with the nodes it addresses (R8's clock). Its memory grows with the stretch: :meth:`clear` between
    stretches (a long run's consumers keep sinks of their own)."""

    wants_commands = True

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        #: per request (its time, service, transfer id, requester): the first answer to it (can id, time), and who
        self.answers: dict[tuple, tuple[int, float, int]] = {}
        #: per GET_ESC_ID query (its time, its source): the reply that answers it alone (can id, time, node)
        self.replies: dict[tuple[float, int], tuple[int, float, int]] = {}
        #: the queries (time, source) a reply may answer with another node's: which, the bus cannot tell
        self.ambiguous: set[tuple[float, int]] = set()
        #: (can id, time) of every answer paired with a request or a query (the rest answer none)
        self.paired: set[tuple[int, float]] = set()
        #: per (node, report name): each report's time and whether its counter started again (R9a)
        self.reports: dict[tuple[int, str], list[tuple[float, bool]]] = {}
        #: per node: each MSG1's time, comm flag and the last command before it that addresses it (None: none yet)
        self.flags: dict[int, list[tuple[float, bool, float | None]]] = {}
        #: per node: the times of the throttle commands that address its channel, as told (one heard before its Set ID
        #: answer said the channel comes with the answer: sort them)
        self.commands: dict[int, list[float]] = {}

    @staticmethod
    def key(t: float, service: int, transfer_id: int | None, requester: int) -> tuple:
        """A request's key in :attr:`answers` (a host frame's timestamp, type id, transfer id, source)."""
        return (t, service, transfer_id, requester)

    def response(self, ts: float, node: int, pairing: ResponsePairing, can_id: int, data: bytes) -> None:
        r = pairing.request
        if r is None or pairing.again:
            return
        self.answers.setdefault(self.key(r.t, r.service, r.transfer_id, r.requester), (can_id, ts, node))
        self.paired.add((can_id, ts))

    def reply(self, ts: float, node: int, pairing: ReplyPairing, can_id: int, data: bytes) -> None:
        could = pairing.could
        if not could:
            return
        self.paired.add((can_id, ts))
        if len({q.source for q in could}) == 1:  # one node's query: the earliest it may answer, as the pairing takes it
            self.replies.setdefault((could[0].t, could[0].source), (can_id, ts, node))
        else:
            self.ambiguous.update((q.t, q.source) for q in could)

    def report(self, ts: float, node: int, name: str, restarted: bool) -> None:
        self.reports.setdefault((node, name), []).append((ts, restarted))

    def msg1(self, ts: float, node: int, flag: bool, last_command: float | None) -> None:
        self.flags.setdefault(node, []).append((ts, flag, last_command))

    def command(self, ts: float, node: int) -> None:
        self.commands.setdefault(node, []).append(ts)
