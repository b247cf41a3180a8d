"""The DUT profile as a conformance statement, checked against the device (issue #29; as Matter checks a PICS
file against the device it describes).

:func:`observe` asks the DUT what a profile states of it that the DUT itself can show, **with reads only**: no
setting is written and no throttle sent. It asks which ESCs answer GET_ESC_ID (capability ``multi_node`` on a
real bus), ESC Information (240), Maintenance Information (241, options 0-2), Get Major Configuration (242), reads
one MSG3 (its Motor_T: capability ``motor_temperature``), and asks for the optional functions (R9b) that have a
read: Get Rec (223: MSG_EXP12 records, R15) and Expand Set Part's one read, 0xFFFB part 1 "Read out high
temperature records" (222, R14; it can only show where Get Rec shows records). MSG_EXP mode and CAN Test are modes,
not reads: they are tried only with ``modes=True`` (each switched on, looked at and switched off again at once;
neither is kept across a power cycle, R13, R16).

:func:`contradictions` says where a profile and what was observed disagree: warnings, never a verdict (a claim the
DUT contradicts makes the run's tests of it SKIPPED or FAILed for the wrong reason, so the bench's owner should
know before reading the verdicts). :func:`profile_toml` writes a profile of what was observed, with a comment
for everything it could not learn.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from ..protocol import catalogue as cat
from ..protocol.functions import OPTIONAL
from .link import DutError, Link
from .profile import DutProfile

#: how long a function is given to show itself after it was asked (the records of Get Rec come as MSG_EXP12
#: frames, whose timing is R15's business, not this probe's): an allowance, not a protocol fact
ANSWER_WINDOW_S = 0.5
#: Get Rec payloads tried in turn: the document gives none (R15-payload: OBSERVE), as section 4.4.14's tests try
GET_REC_PAYLOADS = ([], [0x00])
#: Expand Set Part's read (4.4.25): "Read out high temperature records"
RECORD_READ = next(c for c in cat.EXPAND_COMMANDS.values() if c.name == "read_temperature_records")
#: frames that only MSG_EXP mode sends (MSG_EXP12 comes on request)
EXP_MODE_FRAMES = frozenset(f"msg_exp{n}" for n in range(1, 12))


@dataclass
class Seen:
    """Whether a function showed itself: True it did, False it was asked and did not, None not asked or cannot
    tell; ``how``: what was asked and what came."""

    answered: bool | None
    how: str


@dataclass
class Observed:
    """What the DUT showed of itself (:func:`observe`)."""

    node_id: int
    nodes: list[int]  # every node that answered GET_ESC_ID
    esc_information: dict[str, Any] | None = None
    maintenance: dict[int, dict[str, Any] | None] = field(default_factory=dict)
    major_configuration: dict[str, Any] | None = None
    motor_t: int | None = None  # MSG3 Motor_T (degC); None: no MSG3 heard
    functions: dict[str, Seen] = field(default_factory=dict)


def probe_link(link: Link) -> Link:
    """A link to the same DUT whose profile declares nothing absent: a function declared absent is asked too."""
    probe = Link(link.lane, replace(link.profile, absent=()), node_id=link.node_id, host_node=link.host_node)
    if hasattr(link, "discovered"):
        probe.discovered = link.discovered
    return probe


def observe(link: Link, *, modes: bool = False, full: bool = True) -> Observed:
    """Ask the DUT at ``link.node_id`` (reads only; with ``modes`` also MSG_EXP mode and CAN Test, each left at once).
    ``link``'s profile must declare nothing absent (:func:`probe_link`). Without ``full`` only which nodes answer
    and the optional functions (what ``ckesc run`` checks at its start: it reads 240 itself, and MSG3's Motor_T is
    section 4.4.6's business)."""
    node = link.node_id
    discovered = getattr(link, "discovered", None)  # the link found the DUT by GET_ESC_ID: who answered is known
    obs = Observed(node_id=node, nodes=sorted(discovered) if discovered else _answering(link))
    if node not in obs.nodes:  # nothing it does not answer says anything of its functions
        heard = f"nodes {', '.join(map(str, obs.nodes))} answer" if obs.nodes else "no node answers"
        raise DutError(f"node {node} does not answer GET_ESC_ID ({heard})")
    longest = _longest_interval(None)
    if full:
        obs.esc_information = _fields(link, "esc_information", {"option": 0})
        obs.maintenance = {option: _fields(link, "maintenance_information", {"option": option}) for option in (0, 1, 2)}
        obs.major_configuration = _fields(link, "get_major_configuration", {"option": 0})
        longest = _longest_interval(obs.major_configuration)
        msg3 = link.frames("msg3", source=node) or [link.wait_for("msg3", 2 * longest + 2 * link.lane.timing_error)]
        obs.motor_t = msg3[-1].fields["motor_t"] if msg3[-1] is not None else None

    records = _get_rec(link)
    obs.functions["get_rec"] = records
    obs.functions["expand_set_part"] = _record_read(link, records)
    if modes:
        obs.functions["msg_exp_mode"] = _exp_mode(link, longest)
        obs.functions["can_test"] = _can_test(link, longest)
    else:
        for name, what in (("msg_exp_mode", "MSG Control 0xEEEEEEEE"), ("can_test", "CAN Test 0xAA")):
            obs.functions[name] = Seen(None, f"not asked: {what} switches a mode, not a read (`ckesc profile check --modes` asks it)")
    return obs


def _answering(link: Link) -> list[int]:
    sent = link.broadcast("get_esc_id", {"option": 0}, layout="query")
    link.wait(2 * cat.ANSWER_DELAY_MAX_S + 2 * link.lane.timing_error)
    return sorted({f.source for f in link.frames("get_esc_id", since=sent.time)
                   if f.layout is not None and f.layout.name == "reply"})


def _fields(link: Link, name: str, fields: dict[str, Any]) -> dict[str, Any] | None:
    try:
        ex = link.request(name, fields)
    except DutError:
        return None
    return dict(ex.response.fields) if ex.response is not None else None


def _longest_interval(config: dict[str, Any] | None) -> float:
    """The longest report interval 242 shows (s), else the longest the document allows."""
    codes = [config[k] for k in cat.INTERVAL_FIELDS if config and config.get(k)]
    return max(codes or [cat.REPORT_INTERVAL_RANGE[1]]) * cat.INTERVAL_UNIT_S


def _records_since(link: Link, since: float) -> int:
    node = link.node_id
    return len(link.frames("msg_exp12", since=since, source=node)) + len(link.undecoded("msg_exp12", since=since, source=node))


def _await_records(link: Link, since: float) -> int:
    """Read until a MSG_EXP12 from the DUT came (then a little longer, for the rest) or the window passed."""
    node = link.node_id
    if _records_since(link, since) == 0:
        link.read_until(since + ANSWER_WINDOW_S + 2 * link.lane.timing_error,
                        stop=lambda f: f.name == "msg_exp12" and f.source == node)
    if _records_since(link, since):
        link.wait(cat.ANSWER_DELAY_MAX_S)
    return _records_since(link, since)


def _get_rec(link: Link) -> Seen:
    for payload in GET_REC_PAYLOADS:
        t = link.now()
        ex = link.request("get_rec", {"payload": payload})
        n = _await_records(link, t)
        if n or ex.response is not None:
            what = f"{n} MSG_EXP12 record(s)" + (" and a Get Rec answer" if ex.response is not None else "")
            return Seen(True, f"Get Rec (223) with payload {bytes(payload).hex() or 'empty'}: {what}")
    return Seen(False, f"Get Rec (223), payload empty and 00: no MSG_EXP12 and no answer within {ANSWER_WINDOW_S:g} s")


def _record_read(link: Link, records: Seen) -> Seen:
    t = link.now()
    link.request("expand_set_part", {"set_cmd": RECORD_READ.code, "part": 1})
    n = _await_records(link, t)
    answered = [f for f in link.frames("expand_set_part", since=t, source=link.node_id)]
    asked = f"Expand Set Part (222) 0x{RECORD_READ.code:04X} part 1 (read the temperature records)"
    if n or answered:
        return Seen(True, f"{asked}: {n} MSG_EXP12 record(s)" + (" and an answer (R14: none is due)" if answered else ""))
    if not records.answered:
        return Seen(None, f"cannot tell without a write: {asked} sent no records, nor did Get Rec (its only read "
                          "shows the records Get Rec shows)")
    return Seen(False, f"{asked}: no MSG_EXP12 within {ANSWER_WINDOW_S:g} s, though Get Rec sends them")


def _exp_mode(link: Link, longest: float) -> Seen:
    t = link.now()
    link.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME_EXP})
    try:
        link.read_until(t + 2 * longest + cat.ANSWER_DELAY_MAX_S + 2 * link.lane.timing_error,
                        stop=lambda f: f.name in EXP_MODE_FRAMES and f.source == link.node_id)
    finally:
        link.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})
        link.wait(cat.ANSWER_DELAY_MAX_S)
    names = sorted({f.name for f in link.frames(since=t, source=link.node_id) if f.name in EXP_MODE_FRAMES})
    asked = "MSG Control 0xEEEEEEEE (then 0xAAAAAAAA)"
    if names:
        return Seen(True, f"{asked}: {', '.join(names)}")
    return Seen(False, f"{asked}: no MSG_EXP frame within {2 * longest + cat.ANSWER_DELAY_MAX_S:.2f} s")


def _can_test(link: Link, longest: float) -> Seen:
    t = link.now()
    link.broadcast("can_test", {"option": cat.CAN_TEST_ON, "count": 0})
    try:
        link.read_until(t + 2 * longest + cat.ANSWER_DELAY_MAX_S + 2 * link.lane.timing_error,
                        stop=lambda f: f.name == "can_test" and f.source == link.node_id)
    finally:
        link.broadcast("can_test", {"option": cat.CAN_TEST_OFF, "count": 0})
        link.wait(cat.ANSWER_DELAY_MAX_S)
        link.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME})  # reporting back, whatever CAN Test did
        link.wait(cat.ANSWER_DELAY_MAX_S)
    n = len(link.frames("can_test", since=t, source=link.node_id))
    asked = "CAN Test 0xAA (then 0x55)"
    return Seen(True, f"{asked}: {n} CAN Test frame(s)") if n else Seen(False, f"{asked}: no CAN Test frame")


# ------------------------------------------------------------------------------------------- checking
def contradictions(profile: DutProfile, obs: Observed, *, bus: bool) -> list[str]:
    """Where ``profile`` claims what ``obs`` shows otherwise, one line each. ``bus``: the DUT is on a real bus
    (``multi_node`` speaks of that bus; the emulator lanes give the multi-ESC tests a bench of their own)."""
    out = []
    for name, seen in obs.functions.items():
        f = OPTIONAL[name]
        if seen.answered and name in profile.absent:
            out.append(f"[functions] absent declares {f.describe()} absent, but the DUT answers ({seen.how}): its tests "
                       "are SKIPPED as not claimed; take it out of `absent` to have them judged")
        elif seen.answered is False and name not in profile.absent:
            out.append(f"the profile claims {f.describe()}, but the DUT does not answer ({seen.how}): its tests will "
                       "FAIL; if this ESC model lacks it, declare it in [functions] absent (R9b)")
    if bus and profile.has("multi_node") and len(obs.nodes) < 2:
        out.append(f"[capabilities] multi_node = true, but only node {obs.nodes[0]} answers GET_ESC_ID")
    elif bus and not profile.has("multi_node") and len(obs.nodes) > 1:
        out.append(f"nodes {', '.join(map(str, obs.nodes))} answer GET_ESC_ID, but [capabilities] multi_node is not "
                   "true: the multi-ESC tests are SKIPPED")
    if obs.motor_t is not None:
        if profile.has("motor_temperature") and obs.motor_t == 0:
            out.append("[capabilities] motor_temperature = true, but MSG3 reports Motor_T = 0 (no sensor?)")
        elif not profile.has("motor_temperature") and obs.motor_t != 0:
            out.append(f"MSG3 reports Motor_T = {obs.motor_t} degC, but [capabilities] motor_temperature is not true: "
                       "Motor_T is not checked")
    return out


# ------------------------------------------------------------------------------------------- writing
def _toml_str(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _name(obs: Observed) -> str:
    info = obs.esc_information
    if not info:
        return f"ESC at node {obs.node_id}"
    return (f"ESC hardware {info['hardware_version']}, firmware {2000 + info['firmware_year']}-"
            f"{info['firmware_month']:02d}-{info['firmware_day']:02d}")


def profile_toml(obs: Observed, *, opened_with: DutProfile, bus: bool, bench: str, timing_error: float) -> str:
    """A profile of what ``obs`` shows, with a comment for every key it could not learn. ``opened_with``: the
    profile the bench was opened with (its timing is written as the starting point to measure from); ``bench``:
    one line saying which bench was asked; ``timing_error``: the lane's stated error."""
    info = obs.esc_information
    lines = [
        "# Written by `ckesc profile init` from what the DUT answered to reads (nothing was written to it):",
        f"# {bench}",
        f"# ESC Information (240): {info if info is not None else 'no answer'}",
    ]
    for option, fields in obs.maintenance.items():
        lines.append(f"# Maintenance Information (241) option {option}: {fields if fields is not None else 'no answer'}")
    lines.append(f"# Get Major Configuration (242): {obs.major_configuration if obs.major_configuration is not None else 'no answer'}")
    lines += [
        "# Check every key marked 'state' or 'measure': what a read cannot show is left at a stated default.",
        "",
        "[dut]",
        f"name = {_toml_str(_name(obs))}  # state: how the reports name the DUT",
        f"description = {_toml_str(_description(obs))}",
        "",
        "[capabilities]",
        "led = false                # state: a read cannot show an LED (Set Led is a write)",
        "motor = false              # state: whether a motor is attached (spinning it still needs --allow-motor-spin)",
        "pwm_input = false          # state: whether the bench can drive a PWM throttle input",
    ]
    if obs.motor_t is None:
        lines.append("motor_temperature = false  # state: no MSG3 was heard, so its Motor_T was not seen")
    else:
        lines.append(f"motor_temperature = {str(obs.motor_t != 0).lower():<5}  # MSG3 Motor_T = {obs.motor_t} degC "
                     "(0 taken as no sensor): state it if wrong")
    if bus:
        many = len(obs.nodes) > 1
        lines.append(f"multi_node = {str(many).lower():<5}         # node(s) {', '.join(map(str, obs.nodes))} answered "
                     "GET_ESC_ID")
    else:
        lines.append("multi_node = true          # --dut emulator: the multi-ESC tests get an emulated bench of their own")
    lines += [
        "",
        "[timing]",
        f"error_s = {max(timing_error, opened_with.error_s):g}  # measure: the bench's timestamp error (host + adapter), "
        f"here as the bench was opened with profile {opened_with.name!r}; see docs/bench/qualification.md",
        f"jitter_s = {opened_with.jitter_s:g}  # state: the DUT's report-interval jitter allowance beyond the suite's own (R9)",
        f"boot_s = {opened_with.boot_s:g}  # measure: power-on to first report",
        f"off_s = {opened_with.off_s:g}  # measure: how long a power cycle keeps it off",
        "",
        "[readings]",
        'R4 = "lsb"  # state: RawCommand_12b\'s nibble order; only throttle shows it (section 4.4.16\'s tests tell)',
        "",
        "[functions]",
    ]
    absent = [name for name, seen in obs.functions.items() if seen.answered is False]
    for name, seen in obs.functions.items():
        verdict = {True: "answers", False: "ABSENT", None: "not learnt (kept claimed)"}[seen.answered]
        lines.append(f"# {name}: {verdict}: {seen.how}")
    lines.append(f"absent = [{', '.join(_toml_str(n) for n in absent)}]")
    return "\n".join(lines) + "\n"


def _description(obs: Observed) -> str:
    info = obs.esc_information
    if not info:
        return "ESC Information (240) not answered"
    return (f"max {info['max_cells']} S, {info['max_current'] * 10} A, protocol file version {info['protocol_version']} "
            "(from ESC Information, 240)")

