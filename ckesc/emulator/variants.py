"""Conforming variants: every behaviour the document leaves free, as the emulator can play it.

A fault (``faults.py``) makes an emulated ESC break a rule; a *variant* makes it take another of the
choices the document, or a stated READING, allows. The suite must pass every variant: a FAIL or an
ERROR on one is the suite's bug (a reading stricter than the document), never the DUT's. This module
is the one list of those freedoms, each citing the requirement ids (``ckesc/protocol/requirements.toml``:
``R..`` from ``spec/INTERPRETATIONS.md``, section clauses) that leave it open.

Each freedom is an :class:`~ckesc.emulator.config.EscConfig` field, whose default it gives. Its conforming
values are either named alternatives (``choices``; the first is what the emulator does by default) or a span
of seconds (``span``, with its ``default`` inside it). ``--emulator-option NAME=VALUE`` (``ckesc
run``, the pytest plugin) and ``ckesc emulate --option NAME=VALUE`` set one; ``--emulator-variants SEED``
and ``ckesc emulate --variants SEED`` draw a whole combination from a seed (:func:`draw`), options
given by name winning over the draw.
"""

from __future__ import annotations

import difflib
import random
import textwrap
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any, Iterable, Mapping

from ..protocol import catalogue as cat


class VariantError(ValueError):
    """A variant name or value the emulator cannot play (a usage error, said in one line)."""


@dataclass(frozen=True)
class Freedom:
    name: str  # the EscConfig field it sets
    allowed_by: tuple[str, ...]  # requirement ids whose text leaves this open
    description: str
    choices: tuple[str, ...] = ()  # named conforming alternatives; the first is the emulator's default
    #: or: a number of seconds, drawn in [lo, hi]; any value >= 0 is taken (whether it conforms is the DUT profile's
    #: to say, e.g. boot_time + report_delay within its boot_s)
    span: tuple[float, float] | None = None
    #: what the emulator does by default (EscConfig's field takes it from here): a span's value inside it; a choice
    #: freedom's is its first choice, never given
    default: Any = None
    #: a DUT profile [timing] key the emulated DUT declares as this value (what a vendor would state in its
    #: profile for an ESC that behaves so; e.g. its report jitter is its ``jitter_s``)
    declares: str | None = None

    def __post_init__(self) -> None:
        if bool(self.choices) == (self.span is not None):
            raise ValueError(f"freedom {self.name}: give either choices or a span")
        if self.choices:
            if self.default is not None:
                raise ValueError(f"freedom {self.name}: a choice's default is its first choice")
            object.__setattr__(self, "default", self.choices[0])
        elif self.default is None or not self.span[0] <= self.default <= self.span[1]:  # type: ignore[index]
            raise ValueError(f"freedom {self.name}: its default must lie in its span")

    @property
    def kind(self) -> str:
        return "seconds" if self.span is not None else "choice"

    def values_text(self) -> str:
        if self.span is not None:
            return f"{self.span[0]:g}..{self.span[1]:g} s"
        return "|".join(self.choices)

    def parse(self, text: Any) -> Any:
        """A value given as text (or already typed), checked against what conforms."""
        if self.span is not None:
            try:
                value = float(text)
            except (TypeError, ValueError):
                raise VariantError(f"{self.name}: seconds ({self.values_text()}), got {text!r}") from None
            if not value >= 0:  # the span is what a draw takes; beyond it a value conforms where the DUT profile says so
                raise VariantError(f"{self.name}: seconds, 0 or more, got {text!r}")
            return value
        value = str(text)
        if value not in self.choices:
            raise VariantError(f"{self.name}={value}: one of {self.values_text()} ({', '.join(self.allowed_by)})")
        return value

    def draw(self, rng: random.Random) -> Any:
        if self.span is not None:
            return round(rng.uniform(*self.span), 4)
        return rng.choice(self.choices)


#: above_half_load=drop (R18-above-half: what an ESC does above half load is free): a report due when foreign frames
#: took more than this share of the bus in the window before it is skipped. Between the half R18 judges and the 70 %
#: the suite plays above it: at half load a window holds at most half of it plus R18_BURST_FRAMES longest frames of
#: load (4.2 ms at 125 kbit/s, one more for a frame that began before the window: 55 ms of 0.1 s), at 70 % at least
#: 70 % of it less one burst (2 ms)
ABOVE_HALF_SHARE = 0.6
ABOVE_HALF_WINDOW_S = 0.1

# Each freedom names the field of EscConfig it sets; keep one entry per freedom, grouped by where the
# document leaves it open. New freedoms go in the group of their requirement.
_FREEDOMS = (
    # power-up (profile [timing] boot_s: power-on to the first report; the emulator profile says 0.5 s, and the
    # spans drawn from keep boot_time + report_delay + ckesc emulate's --boot-spread inside it)
    Freedom("boot_time", ("1-2",), "power-on to the first answer: the ESC hears nothing before",
            span=(0.05, 0.3), default=0.25),
    Freedom("report_delay", ("1-2",), "boot to the first report: an ESC may answer services before it reports",
            span=(0.0, 0.15), default=0.0),
    # report timers (R9a)
    Freedom("report_timer", ("R9a",),
            "when reporting comes back (a resume, leaving CAN Test or MSG_EXP mode): restart (the first report at once, "
            "the next ones an interval apart), grid (one report at once, then the old grid goes on), next_tick (the "
            "first report at the old grid's next point) or one_interval (the timer restarted: the first one interval "
            "later)",
            choices=("restart", "grid", "next_tick", "one_interval")),
    Freedom("set_freq_timer", ("R9a",),
            "when a report whose interval a Set Freq write changed comes next: last_report (the new interval from the "
            "last report), old_deadline (the report already scheduled on the old interval, then the new interval from "
            "it), restart (one new interval after the write) or at_once (a report at the write, then the new interval)",
            choices=("last_report", "old_deadline", "restart", "at_once")),
    Freedom("report_jitter_s", ("R9",),
            "the ESC's own report timing jitter, declared as its profile's jitter_s: each report within +- half of it "
            "of its grid point (one interval strays by at most this much; the mean interval stays exact)",
            span=(0.0, 0.003), default=0.0, declares="jitter_s"),
    # comm loss (R8): the flag is set no earlier than 200 ms after the last command, and shows in MSG1 no later
    # than one MSG1 interval after that; where in between the ESC raises it is its own
    Freedom("comm_loss_check", ("R8", "4.4.4-3"),
            "when the comm-loss flag is raised: timer (an exact 200 ms timer from the last command), msg1 (checked "
            "only when an MSG1 is due: the first one 200 ms or more after the last command carries it) or tick (a "
            "periodic check on the report timer's 2 ms tick, MSG1's grid: the first tick 200 ms or more after it)",
            choices=("timer", "msg1", "tick")),
    # answer slots (R2): node n's slot is [n x 2 ms, n x 2 ms + 2 ms] after the request (n = node_id % 32), the 32
    # slots tiling the 64 ms; the answer frame starts no earlier than its slot and ends inside it
    Freedom("answer_place", ("R2", "4.4.2-4", "4.4.3-4"),
            "where in its 2 ms slot an answer to MSG Control / GET_ESC_ID goes: start (at the slot's start), inside "
            "(a random place, the frame ending inside the slot) or late (as late as leaves room for one frame on "
            "the bus ahead of it, the answer still ending inside the slot)",
            choices=("start", "inside", "late")),
    # power-up order of the reports (R9a: each report's first within one interval of power-up; their phase is free)
    Freedom("report_phase", ("R9a", "R9a-gaps"),
            "the first MSG1, MSG2 and MSG3 after power-up: together, or staggered (MSG2 7 ms, MSG3 13 ms after MSG1)",
            choices=("together", "staggered")),
    # framing (F3: +1 per transfer, modulo 32; the first value after power-up is not written)
    Freedom("transfer_id_start", ("F3",), "each message transfer-id counter's first value after power-up: 0, "
            "or a random one (then +1 per transfer)", choices=("zero", "random")),
    # priorities (F5-unlisted: 240/241/242 have none in 4.3.2's table)
    Freedom("unlisted_priority", ("F5-unlisted",), "the priority of 240/241/242 answers: the request's, or a fixed one",
            choices=("request", "medium", "low", "lowest")),
    # malformed frames (R17: a single frame with toggle 1 may be taken or ignored)
    Freedom("toggle_single_frame", ("R17-toggle",), "a single frame (start=1 end=1) whose toggle bit is 1: ignored "
            "as not a single-frame transfer, or taken as DroneCAN's receiver (libcanard) takes it",
            choices=("ignore", "take")),
    # a loaded bus (R18: up to half the bus the ESC keeps R9, R2, the 64 ms bound; above half what it does is OBSERVE)
    Freedom("above_half_load", ("R18-above-half",), "foreign traffic above half the bus: reports kept, or a report "
            f"dropped when foreign frames took more than {ABOVE_HALF_SHARE:.0%} of the bus in the "
            f"{ABOVE_HALF_WINDOW_S:g} s before it is due (never at half load or less)", choices=("keep", "drop")),
    # host node (F6: a non-zero host node is OBSERVE)
    Freedom("foreign_host", ("F6",), "commands and requests from a host node other than 0: obeyed, or ignored",
            choices=("accept", "ignore")),
    # service answers (4.4.2-4's 64 ms bound is the longest delay the document names; services name none)
    Freedom("service_delay", ("4.4.2-4",), "request to answer for services (Set ID .. 242)", span=(0.0002, cat.ANSWER_DELAY_MAX_S),
            default=0.0005),
    # illegal or refused requests (R10: answered or not, and with what, is OBSERVE; R11/R12 refuse without saying
    # what is answered)
    Freedom("rejected_answer", ("R10", "R11", "R12"),
            "a request with an illegal value, or refused (outside the 120 s window, while suspended, motor running): "
            "answered with the current values, not answered, or answered with the request's values echoed "
            "while nothing is applied", choices=("current", "none", "echo")),
    # throttle above its maximum (R6)
    Freedom("over_max_throttle", ("R6",), "a throttle value above 2000 (14/12-bit) or 1000 (10-bit): clamped to the "
            "maximum, the frame's value ignored (the throttle held), or taken as zero",
            choices=("clamp", "hold", "zero")),
    # MSG_EXP mode (R9-exp: which MSG_EXP frames come and how often is OBSERVE)
    Freedom("exp_frames", ("R9-exp",), "in MSG_EXP mode: EXP1 at MSG1's interval and EXP7..11 at MSG3's (msg3), "
            "all of them at MSG2's (msg2), EXP1 only, or EXP7..11 only", choices=("msg3", "msg2", "exp1_only", "no_exp1")),
    # rounding where the document names a unit but no rounding (4.4.5-T .. 4.4.11-T, 4.4.27)
    Freedom("value_rounding", ("4.4.5-T", "4.4.6-T", "4.4.27-T"),
            "temperatures, run times, voltage and current to their units: temperatures and run times truncated, "
            "voltage and current rounded (mixed), all rounded, or all truncated", choices=("mixed", "round", "truncate")),
    # CAN Test (R16: the count grows by one per frame; where it starts is not written)
    Freedom("can_test_count", ("R16",), "CAN Test's count: from 0 at power-up and on across CAN Test sessions, from "
            "a random value, or from 0 at each CAN Test on", choices=("from_zero", "from_random", "zero_each_session")),
    # Set LED blink codes other than 0/1/2/5 (4.4.20: "No operation is performed, no blinking")
    Freedom("led_blink_other", ("4.4.20-4", "4.4.20-T"), "a Set LED blink code other than 0/1/2/5: the colour set "
            "and no blinking, or no operation at all", choices=("no_blink", "no_operation")),
    # Get Major Configuration's other options (4.4.28-2: "Option Indicates the ESC type", against "Fixed to 0")
    Freedom("major_config_option", ("4.4.28-2",), "242 with an option other than 0: answered as option 0, or not",
            choices=("answer", "ignore")),
    # Get Rec / Clear Rec (R15-payload: whether they are answered is OBSERVE)
    Freedom("rec_answer", ("R15-payload",), "Get Rec / Clear Rec requests: no answer (the records come as MSG_EXP12), "
            "or also a service answer echoing the request", choices=("none", "echo")),
)

FREEDOMS: Mapping[str, Freedom] = MappingProxyType({f.name: f for f in _FREEDOMS})


def default(name: str) -> Any:
    """What the emulator does for freedom ``name`` unless told otherwise: the default of EscConfig's field."""
    return FREEDOMS[name].default


def freedom(name: str) -> Freedom:
    try:
        return FREEDOMS[name]
    except KeyError:
        close = difflib.get_close_matches(name, list(FREEDOMS), n=3)
        raise VariantError(f"unknown emulator option {name!r}" + (f" (did you mean {', '.join(close)}?)" if close else "")
                           + f"; one of {', '.join(FREEDOMS)}") from None


def parse(items: Iterable[str]) -> dict[str, Any]:
    """``NAME=VALUE`` items, checked: {EscConfig field: value}."""
    out: dict[str, Any] = {}
    for item in items:
        name, sep, value = str(item).partition("=")
        if not sep:
            raise VariantError(f"takes NAME=VALUE with NAME one of {', '.join(FREEDOMS)}; got {item!r}")
        out[name.strip()] = freedom(name.strip()).parse(value.strip())
    return out


def check(values: Mapping[str, Any]) -> dict[str, Any]:
    """Typed values (an EscConfig's, a rig file's), checked as :func:`parse` checks text."""
    return {name: freedom(name).parse(value) for name, value in values.items()}


def draw(seed: int, names: Iterable[str] | None = None) -> dict[str, Any]:
    """A random conforming combination: every freedom (or those ``names``) at a value drawn from ``seed``.
    The same seed draws the same combination, whatever else changes in the run."""
    rng = random.Random(f"ckesc-variants-{seed}")
    chosen = list(FREEDOMS) if names is None else [freedom(n).name for n in names]
    return {name: FREEDOMS[name].draw(rng) for name in chosen}


def alternatives(f: Freedom) -> list[Any]:
    """Every value of a freedom other than the emulator's default: its other choices, or a span's two ends."""
    if f.span is not None:
        return [v for v in f.span if v != f.default]
    return list(f.choices[1:])


def each() -> list[dict[str, Any]]:
    """One variant per alternative of every freedom, the others at their defaults: what a FAIL is pinned to."""
    return [{f.name: value} for f in FREEDOMS.values() for value in alternatives(f)]


def covering() -> list[dict[str, Any]]:
    """The fewest combinations that play every alternative of every freedom at least once (combination i takes
    each freedom's alternative i, cycling): a cheap run of them all, e.g. in every CI run."""
    alts = {f.name: alternatives(f) for f in FREEDOMS.values()}
    n = max((len(a) for a in alts.values()), default=0)
    return [{name: a[i % len(a)] for name, a in alts.items() if a} for i in range(n)]


def combination(options: Iterable[str] = (), seed: int | None = None) -> dict[str, Any]:
    """What a run plays: the combination drawn from ``seed`` (none: the defaults), with ``options``
    (``NAME=VALUE``) on top."""
    return {**(draw(seed) if seed is not None else {}), **parse(options)}


def declared(values: Mapping[str, Any]) -> dict[str, float]:
    """The DUT profile [timing] keys the emulated ESC declares for this combination (e.g. its jitter)."""
    out: dict[str, float] = {}
    for name, value in values.items():
        f = FREEDOMS.get(name)
        if f is not None and f.declares:
            out[f.declares] = max(out.get(f.declares, 0.0), float(value))
    return out


def describe(values: Mapping[str, Any]) -> str:
    """One line for reports and the console: ``report_timer=grid boot_time=0.12``."""
    return " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in values.items()) or "defaults"


def table() -> str:
    """The freedoms as a text table (``ckesc emulate --list-variants``)."""
    rows = [(f.name, f.values_text(), ", ".join(f.allowed_by), f.description) for f in FREEDOMS.values()]
    w = [max(len(r[i]) for r in rows) for i in range(2)]
    # name, values and the ids on one line; the description wrapped under it (a 100-column terminal)
    return "\n".join(f"{a:<{w[0]}}  {b:<{w[1]}}  ({c})\n" + textwrap.fill(d, 100, initial_indent="    ",
                                                                           subsequent_indent="    ")
                     for a, b, c, d in rows)
