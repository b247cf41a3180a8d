"""The soak's watches' common ground, sans-IO: what a watch is (:class:`Watch`: a property judged, its trials and
events), what it found (:class:`SoakFinding`, with the frames around it), what it knows of the bench and the DUT
(:class:`WatchConfig`), and the bounds that keep a day's run in flat memory."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Iterable, Mapping, Protocol

from ..protocol import catalogue as cat

#: frames kept before a finding (the ring) and read after it
RING_FRAMES = 40
AFTER_FRAMES = 10
#: findings kept whole; past these only counted (a DUT that breaks a rule all the time must not fill the memory)
MAX_FINDINGS = 100
#: ... and at most this many of one watch (a watch finding all the time must not hide the others' findings)
MAX_FINDINGS_PER_WATCH = 20
#: the host's frames kept with their send times, and messages kept decoded (a DUT sending ever new ones must not grow the
#: memory; what each CAN id is, the bus reader keeps, within its own bound)
MAX_IDS = 4096
#: the report frames R9 and the reset watch follow
REPORTS = cat.REPORT_FRAMES


@dataclass
class SoakFinding:
    """One thing a watch found: when (s into the run), which watch, the requirements, what, and the frames around it
    (candump lines with times into the run)."""

    t: float
    watch: str
    rules: tuple[str, ...]
    message: str
    before: list[str] = field(default_factory=list)
    after: list[str] = field(default_factory=list)
    file: str | None = None  # the file of the run's trace holding these frames (--trace-budget), once written

    def to_json(self) -> dict[str, Any]:
        return {"t_s": round(self.t, 6), "watch": self.watch, "rules": list(self.rules), "message": self.message,
                "frames_before": self.before, "frames_after": self.after, "frames_file": self.file}

    def line(self) -> str:
        return f"{clock(self.t)} [{' '.join(self.rules)}] {self.watch}: {self.message}"


def clock(seconds: float) -> str:
    """``3725.5`` -> ``1:02:05.500`` (a time into the run)."""
    whole = int(seconds)
    h, rest = divmod(whole, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}.{int(round((seconds - whole) * 1000)) % 1000:03d}"


@dataclass(frozen=True)
class WatchConfig:
    """What the watches need to know of the bench and the DUT: node ids, the report intervals (s) the DUT was set to
    at the start, the bench's timing error (s; its own frames' error ``own_error``), the DUT's declared jitter, the
    bit rate (frame durations)."""

    node_id: int
    host_node: int
    intervals: Mapping[str, float]
    error: float = 0.0
    own_error: float = 0.0
    jitter: float = 0.0
    bitrate: int = cat.DEFAULT_BITRATE
    nibble_order: str = "lsb"
    #: the host's stream frames one tick sends: each, at the highest priority, may be queued ahead of an answer
    stream_frames: int = 1


class Monitoring(Protocol):
    """What a watch holds of the monitor that feeds it (:class:`.monitor.Monitor`, which imports the watches: they
    import this, not it): its configuration, its start, where a finding goes, and the other watches it names."""

    cfg: WatchConfig
    t0: float
    last_t: float  #: the time of the last frame heard (any node's)
    intervals: Any
    unexpected: Any
    decoder: Any
    rules: Any  #: the bus reader (:class:`~ckesc.evidence.rules.BusRules`): its statistics

    def found(self, watch: Watch, t: float, message: str, rules: tuple[str, ...]) -> None: ...


class Watch:
    """A watched property: its name, the requirement(s) it judges, how many times it was judged (``trials``) and how
    many events broke it (``events``). ``statement_unit``: ``hour`` (events per hour of run) or what a trial is."""

    name = ""
    rules: tuple[str, ...] = ()
    statement_unit = "hour"
    what = ""  # the events, for the statement: "resets"
    one = ""  # one event: "reset"

    def __init__(self, monitor: Monitoring) -> None:
        self.monitor = monitor
        self.cfg = monitor.cfg
        self.trials = 0
        self.events = 0

    def find(self, t: float, message: str, rules: Iterable[str] | None = None) -> None:
        self.events += 1
        self.monitor.found(self, t, message, tuple(rules) if rules is not None else self.rules)

    def statistics(self) -> dict[str, Any]:
        return {}

    def close(self, now: float) -> None:
        """The run ended at ``now``: judge what is still open."""
