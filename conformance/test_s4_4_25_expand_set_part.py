"""Spec section 4.4.25: Expand Set Part (222) - extended settings by (Set_cmd, Part), never answered.

A setting made with 222 must show where the general commands show theirs (4.4.25-2): direction in
242 and the Set Rotation query, LED colour and throttle source in 242, and every setting in
MSG_EXP7 (4.4.9), whose nibbles use the same codes as the Parts; tests whose verdict rests on those
read-backs also cite 4.4.28-1 / 4.4.9-T. MSG_EXP7 comes in MSG_EXP mode
(MSG Control 0xEEEEEEEE; the ``dut`` fixture resumes normal reporting afterwards). Settings that
only MSG_EXP7 shows are put back by the tests that change them; the ``dut`` fixture restores the rest.
Get Rec (223) and Clear Rec (224) are tested with 4.4.14.
"""

import pytest

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import classify
from ckesc.protocol.ids import Kind
from ckesc.protocol.legality import illegal_cases

from . import throttle
from .settings import change, changes

SECTION = "4.4.25"
SPEC = cat.spec("expand_set_part")
CMD = {c.name: c for c in cat.EXPAND_COMMANDS.values()}
EXP7 = {f.name: f for f in cat.spec("msg_exp7").layouts[0].fields}
ROTATION = cat.spec("set_rotation").response.field("rotation").codes  # 0 forward, 1 reverse
SOURCE = cat.spec("throttle_select").request.field("source").codes  # 0 CAN, 1 PWM+CAN
QUERY = next(v for v, n in cat.spec("set_rotation").request.field("rotation").codes.items() if n == "query")
ACT_S = cat.ANSWER_DELAY_MAX_S  # time given to act on a request that is never answered (the longest delay named)
#: command -> its MSG_EXP7 nibble (same codes as the Parts); the document names two of them differently
EXP7_FIELD = {"direction": "direction", "led": "led", "control_mode": "comm_interface",
              "active_freewheel": "active_freewheel", "prop_lock": "prop_lock",
              "startup_acceleration": "startup_acceleration", "lost_signal_reduction": "lost_signal_protection"}
#: settings only MSG_EXP7 shows: put back by the tests that change them
EXP7_ONLY = ("active_freewheel", "prop_lock", "startup_acceleration", "lost_signal_reduction")


def _same(a, b):
    """Names of one setting across tables: 'PWM+TCAN' (222), 'PWM+CAN' (215/242), 'PWM_CAN' (MSG_EXP7)."""
    def norm(s):
        return s.upper().replace("_", "+").replace("TCAN", "CAN")
    return norm(a) == norm(b)


def _code(codes, name):
    return next(v for v, n in codes.items() if _same(n, name))


def _testable_parts(command):
    """The Parts whose setting MSG_EXP7 can show: by name for coded nibbles, in range for numeric ones."""
    field = EXP7[EXP7_FIELD[command.name]]
    if field.codes is not None:
        return [p for p, n in command.parts.items() if any(_same(n, c) for c in field.codes.values())]
    return [p for p in command.parts if field.is_legal(p)]


#: (command, part) cases of 4.4.25-2: every Part of the direction, LED, throttle source (the TCAN ones:
#: MSG_EXP7 names no UAVCAN mode), freewheel and prop lock, and both ends of the numeric ones
CASES = [(name, p) for name in ("direction", "led", "control_mode", "active_freewheel", "prop_lock")
         for p in _testable_parts(CMD[name])]
CASES += [(name, p) for name in ("startup_acceleration", "lost_signal_reduction")
          for p in (min(_testable_parts(CMD[name])), max(_testable_parts(CMD[name])))]
#: never a command: Set_cmd byte-swapped (R14: payload[0] is the low byte), codes the table does not
#: list, Parts it does not list for their Set_cmd; and the '(reserved)' commands
SWAPPED = [("swapped", int.from_bytes(CMD[n].code.to_bytes(2, "little"), "big"), p)
           for n, p in (("direction", 2), ("control_mode", 2))]
UNDEFINED = [("unlisted", c.value, 1) for c in illegal_cases(SPEC, only_enforced=False) if c.field == "set_cmd"]
BAD_PARTS = [("bad-part", CMD["direction"].code, max(CMD["direction"].parts) + 1),
             ("bad-part", CMD["direction"].code, min(CMD["direction"].parts) - 1),
             ("bad-part", CMD["led"].code, max(CMD["led"].parts) + 1)]
RESERVED = [("reserved", c.code, min(c.parts)) for c in cat.EXPAND_COMMANDS.values() if c.reserved]
NOT_COMMANDS = SWAPPED + UNDEFINED + BAD_PARTS + RESERVED
motor_stopped = throttle.motor_stopped  # autouse fixture: the motor stopped before and after each test


def _send(dut, code, part):
    sent = dut.request("expand_set_part", {"set_cmd": code, "part": part})
    dut.wait(ACT_S)
    return sent


def _exp7(dut):
    """The next MSG_EXP7 (in MSG_EXP mode): the settings as the DUT reports them."""
    dut.broadcast("msg_control", {"option": 0, "command": cat.MSG_CONTROL_RESUME_EXP})
    s = dut.settings()
    timeout = 2 * max(s["msg1_interval"], s["msg2_interval"], s["msg3_interval"]) * cat.INTERVAL_UNIT_S + ACT_S
    f = dut.wait_for("msg_exp7", timeout)
    if f is None:
        raise Inconclusive(f"no MSG_EXP7 within {timeout:.2f} s in MSG_EXP mode (which MSG_EXP frames come is OBSERVE, R9)")
    return f.fields


def _shown(dut, name):
    """Where the setting of command ``name`` shows: {place: value} (4.4.25-2)."""
    out = {"MSG_EXP7": _exp7(dut)[EXP7_FIELD[name]]}
    s = dut.settings()
    if name == "direction":
        out["242"] = s["rotation"]
        out["Set Rotation query"] = dut.ask("set_rotation", {"rotation": QUERY})["rotation"]
    elif name == "led" and dut.profile.has("led"):
        out["242"] = s["led_color"]
    elif name == "control_mode":
        out["242"] = s["throttle_source"]
    return out


def _expected(name, part):
    """What each place must show after Part ``part`` of command ``name``."""
    label = CMD[name].parts[part]
    field = EXP7[EXP7_FIELD[name]]
    out = {"MSG_EXP7": _code(field.codes, label) if field.codes else part}
    if name == "direction":
        out["242"] = out["Set Rotation query"] = _code(ROTATION, label)
    elif name == "led":
        out["242"] = int(cat.LedColor[label.upper()])
    elif name == "control_mode":
        out["242"] = _code(SOURCE, label)
    return out


def _other_part(name, part):
    parts = [p for n, p in CASES if n == name]
    return parts[(parts.index(part) + 1) % len(parts)]


def _put_back(dut, exp7):
    """Put the MSG_EXP7-only settings back as ``exp7`` showed them."""
    for name in EXP7_ONLY:
        _send(dut, CMD[name].code, exp7[EXP7_FIELD[name]])
    changed = changes(exp7, _exp7(dut), [EXP7_FIELD[n] for n in EXP7_ONLY])
    if changed:
        raise RuntimeError(f"could not put back the Expand Set Part settings (as found -> now): {changed}")


@pytest.fixture
def put_back(dut):
    """Direction and throttle source as found, put back with 222 itself after the test: the ``dut``
    fixture's Set Rotation / Throttle Select may be what does not work."""
    before = dut.settings()
    yield before
    dut.zero_throttle()
    now = dut.settings()
    if now["rotation"] != before["rotation"]:
        _send(dut, CMD["direction"].code, _direction_part(before["rotation"]))
    if now["throttle_source"] != before["throttle_source"]:
        _send(dut, CMD["control_mode"].code, next(p for p, n in CMD["control_mode"].parts.items()
                                                  if _same(n, SOURCE[before["throttle_source"]])))


@pytest.fixture
def exp7_restored(dut, put_back):
    """MSG_EXP7 as found; its Expand-only settings are put back after the test."""
    before = _exp7(dut)
    try:
        yield before
    finally:
        dut.zero_throttle()
        _put_back(dut, before)


def _other_direction(direction):
    return next(d for d in sorted(ROTATION) if d != direction)


def _direction_part(direction):
    """The Part of Set_cmd 0xFFF0 that names rotation code ``direction``."""
    return next(p for p, n in CMD["direction"].parts.items() if _same(n, ROTATION[direction]))


def _ensure_direction(dut, direction):
    """Setup: ``direction`` in force through 222 (Inconclusive if 222 cannot get it there: that is what
    test_setting_shows_in_the_general_settings judges)."""
    _send(dut, CMD["direction"].code, _direction_part(direction))
    if dut.settings()["rotation"] != direction:
        raise Inconclusive("222 direction did not take with the motor stopped and reporting on "
                           "(see test_setting_shows_in_the_general_settings): this test cannot be judged")


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.25-T", "R14")
def test_not_answered(dut):
    """'no answer frame': a 222 request (the direction in force again) gets no response."""
    sent = _send(dut, CMD["direction"].code, _direction_part(dut.settings()["rotation"]))
    dut.wait(cat.ANSWER_DELAY_MAX_S)
    since = sent.sent.time
    answers = [f for f in dut.frames("expand_set_part", since=since) if f.kind is Kind.RESPONSE]
    garbled = [g.msg for g in dut.garbled if (g.msg.timestamp or 0.0) >= since
               and classify(g.msg.arbitration_id)[:2] == (Kind.RESPONSE, SPEC.type_id)]
    assert not answers and not garbled, f"Expand Set Part was answered: {answers or garbled}"


@pytest.mark.requirement("R14", "4.4.25-T", "4.4.28-1")
@pytest.mark.parametrize("direction", sorted(ROTATION), ids=lambda d: ROTATION[d])
def test_set_cmd_is_little_endian(dut, put_back, direction):
    """Set_cmd 0xFFF0 sent low byte first (F0 FF) sets the direction - reached from the other one."""
    for d in (_other_direction(direction), direction):
        part = _direction_part(d)
        sent = _send(dut, CMD["direction"].code, part)
        dut.record.observe("payload sent", sent.sent.wire.data[:-1].hex(" ").upper())
        assert dut.settings()["rotation"] == d, f"222 direction part {part}: 242 shows {dut.settings()['rotation']}"


@pytest.mark.requirement("4.4.25-2", "4.4.25-T", "R14", "4.4.9-T", "4.4.28-1")
@pytest.mark.parametrize("name,part", CASES, ids=[f"{n}-{CMD[n].parts[p].replace(' ', '')}" for n, p in CASES])
def test_setting_shows_in_the_general_settings(dut, exp7_restored, name, part):
    """Each Part of each command shows in MSG_EXP7, and in 242 / the Set Rotation query where those
    carry the setting - reached from another Part, so that a command that does nothing shows."""
    if name == "led" and not dut.profile.has("led"):
        pytest.skip("the DUT profile has no LED")
    for p in (_other_part(name, part), part):
        _send(dut, CMD[name].code, p)
        shown = _shown(dut, name)
        wrong = changes(_expected(name, p), shown, shown)
        assert not wrong, f"222 {name} part {p} ({CMD[name].parts[p]}, expected -> shown): {wrong}"


@pytest.mark.requirement("R13", "4.4.25-2", "4.4.9-T", "4.4.28-1")
@pytest.mark.power_cycle
@pytest.mark.parametrize("name", ["direction", "prop_lock", "startup_acceleration"])
def test_setting_persists_across_power_cycle(dut, exp7_restored, name):
    """'Expand Set Part settings' persist (R13): shown the same after a power cycle."""
    current = exp7_restored[EXP7_FIELD[name]]
    field = EXP7[EXP7_FIELD[name]]
    parts = [p for n, p in CASES if n == name]
    part = next(p for p in parts if _expected(name, p)["MSG_EXP7"] != current)
    _send(dut, CMD[name].code, part)
    want = _expected(name, part)
    if _shown(dut, name) != {k: want[k] for k in _shown(dut, name)}:
        raise Inconclusive(f"222 {name} part {part} did not take (see test_setting_shows_in_the_general_settings)")
    dut.power_cycle(dut.profile.off_s, dut.profile.boot_s)
    shown = _shown(dut, name)
    lost = changes(want, shown, shown)
    assert not lost, f"a power cycle changed {name} (as set -> after; MSG_EXP7 {field.name}): {lost}"


@pytest.mark.requirement("4.4.25-1", "R12", "4.4.28-1")
@pytest.mark.spins_motor
def test_not_applied_while_the_motor_runs(dut, put_back):
    """'Expand Set Part is required when the motor is stopped': running, a direction change takes no
    effect (not later either). First shown to work with the motor stopped."""
    before = dut.settings()["rotation"]
    other = _other_direction(before)
    _ensure_direction(dut, other)
    _ensure_direction(dut, before)
    throttle.start_motor(dut)
    try:
        _send(dut, CMD["direction"].code, _direction_part(other))
        during = dut.settings()["rotation"]
    finally:
        dut.stop_motor()
    assert during == before, f"222 direction while the motor ran took effect: 242 {change('rotation', before, during)}"
    after = dut.settings()["rotation"]
    assert after == before, f"222 direction sent while running took effect later: 242 {change('rotation', before, after)}"


@pytest.mark.requirement("R12", "4.4.2-3", "4.4.28-1")
def test_not_applied_while_reporting_is_suspended(dut, put_back):
    """'parameter changes do not take effect when the active data reporting command is suspended' (not
    even once reporting resumes). First shown to work with reporting on."""
    before = dut.settings()["rotation"]
    other = _other_direction(before)
    _ensure_direction(dut, other)
    _ensure_direction(dut, before)
    dut.suspend_reporting()
    try:
        _send(dut, CMD["direction"].code, _direction_part(other))
    finally:
        dut.resume_reporting()
    after = dut.settings()["rotation"]
    assert after == before, f"222 direction while suspended took effect: 242 {change('rotation', before, after)}"


@pytest.mark.requirement("4.4.25-T", "R14")
@pytest.mark.parametrize("kind,code,part", NOT_COMMANDS, ids=[f"{k}-{c:#06x}-part{p}" for k, c, p in NOT_COMMANDS])
def test_what_the_table_does_not_define_changes_nothing(dut, exp7_restored, kind, code, part):
    """A Set_cmd the table does not list (byte-swapped ones included, R14), a Part it does not list
    for its Set_cmd, or a '(reserved)' function changes none of the settings 242 and MSG_EXP7 show
    (a reserved function may move MSG_EXP7's reserved nibbles: recorded)."""
    before = _everywhere(dut.settings(), exp7_restored)
    _send(dut, code, part)
    after = _everywhere(dut.settings(), _exp7(dut))
    changed = [k for k in after if before[k] != after[k]]
    dut.record.observe(f"222 ({code:#06x}, {part}) changed", changes(before, after) or "nothing")
    if kind == "reserved":
        changed = [k for k in changed if not k.startswith("MSG_EXP7.") or k[9:] in EXP7_FIELD.values()]
    assert not changed, f"222 ({code:#06x}, {part}) ({kind}) changed {changes(before, after, changed)}"


def _everywhere(settings, exp7):
    """The settings 242 and MSG_EXP7 show, as ``242.<name>`` / ``MSG_EXP7.<field>``."""
    return {f"{where}.{k}": v for where, shown in (("242", settings), ("MSG_EXP7", exp7)) for k, v in shown.items()}


@pytest.mark.requirement("4.4.25-T", "R14", "R15")
def test_read_temperature_records(dut):
    """0xFFFB Part 1 'Read out high temperature records': MSG_EXP12 frames, each naming its record in
    the tail byte (0xC1..0xC5, R15)."""
    sent = _send(dut, CMD["read_temperature_records"].code, 1)
    dut.wait(cat.ANSWER_DELAY_MAX_S)
    records = [f for f in dut.frames("msg_exp12", since=sent.sent.time, source=dut.node_id)]
    tags = [f.transfer_id for f in records]
    dut.record.observe("records (tail tag)", tags)
    assert records, "no MSG_EXP12 after 222 0xFFFB part 1"
    assert all(t in cat.MSG_EXP12_RECORDS for t in tags), f"MSG_EXP12 records tagged {tags} (R15: 0xC1..0xC5)"
    assert len(set(tags)) == len(tags), f"a record came twice: {tags}"
