"""Spec section 4.4.20: Set Led (212) - colour (low three bits RGB) and blink, saved with option 1.

What is in force is read back with Get Major Configuration (242: ``led_color``, ``led_blink``); tests
whose verdict rests on that read-back also cite 4.4.28-1. Each
test first sets something different from what it then sets, so that a command that does nothing
shows. The ``dut`` fixture restores (option 1) and verifies the LED it found.
"""

import pytest

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.legality import illegal_cases

from .settings import changes, check_neighbours_kept, listed, neighbours_moved

SECTION = "4.4.20"
SPEC = cat.spec("set_led")
COLOR = SPEC.request.field("color")
COLOURS = range(COLOR.legal[0], COLOR.legal[1] + 1)  # 4.4.20-3: RGB in the low three bits
COLOUR_MASK = COLOR.legal[1]  # "the lower three bits of Color are valid"
BLINKS = sorted(cat.LED_BLINK)  # 0x00, 0x01, 0x02, 0x05
#: colours with high bits set: the catalogue's out-of-range values, and a few with every low pattern
HIGH_COLOURS = sorted({c.value for c in illegal_cases(SPEC, only_enforced=False) if c.field == "color"}
                      | {(COLOUR_MASK + 1) | 5, 0xF0 | 3, 0xA8 | 6})
UNASSIGNED_BLINKS = [c.value for c in illegal_cases(SPEC, only_enforced=False) if c.field == "blink"]
SAVE, NO_SAVE = 1, 0  # Option: "0: do not save, 1: save"


def _name(colour):
    return "+".join(m.name for m in reversed(cat.LedColor) if m and colour & m) or "off"  # R, G, B as the table


def _led(dut):
    s = dut.settings()
    return s["led_color"], s["led_blink"]


def _differs(want, shown) -> str:
    """Where 242's LED ``shown`` differs from (colour, blink) ``want``: ``led_color 5 -> 3``; "" if nowhere."""
    return changes(dict(zip(("led_color", "led_blink"), want)), dict(zip(("led_color", "led_blink"), shown)))


def _other_colour(colour):
    return COLOURS[(colour - COLOURS[0] + 3) % len(COLOURS)]


def _other_blink(blink):
    return BLINKS[(BLINKS.index(blink) + 1) % len(BLINKS)] if blink in BLINKS else BLINKS[1]


def _set(dut, option, colour, blink):
    return dut.request("set_led", {"option": option, "color": colour, "blink": blink})


def _check_echo(ex, option, colour, blink):
    assert ex.response is not None, "no answer to Set Led"
    got = ex.response.fields
    assert (got["option"], got["color"] & COLOUR_MASK, got["blink"]) == (option, colour, blink), (
        f"Set Led option {option}, color {colour}, blink {blink} answered {listed(got)} "
        "(4.4.20-T: the answer carries Option, Color, Blink)")


def _ensure(dut, option, colour, blink):
    """Setup: the LED at (colour, blink) (Inconclusive if Set Led cannot get it there: that is what
    test_colour_is_set / test_blink_is_set judge)."""
    _set(dut, option, colour, blink)
    if d := _differs((colour, blink), _led(dut)):
        raise Inconclusive(f"Set Led ({option}, {colour}, {blink}) did not take with reporting on: 242 "
                           f"{d} (set -> 242); this test cannot be judged")


# ------------------------------------------------------------------------------------------ tests
@pytest.mark.requirement("4.4.20-1", "4.4.20-3", "4.4.20-T", "4.4.28-1")
@pytest.mark.parametrize("colour", COLOURS, ids=_name)
def test_colour_is_set(dut, colour):
    """Each of the eight RGB combinations is taken, answered and shown by 242."""
    _, blink = _led(dut)
    _set(dut, NO_SAVE, _other_colour(colour), blink)
    ex = _set(dut, SAVE, colour, blink)
    _check_echo(ex, SAVE, colour, blink)
    assert not (d := _differs((colour, blink), _led(dut))), f"after Set Led colour {colour} 242 differs from what was set: {d} (set -> 242)"


@pytest.mark.requirement("4.4.20-1", "4.4.20-T", "4.4.28-1")
@pytest.mark.parametrize("blink", BLINKS, ids=lambda b: cat.LED_BLINK[b].replace(" ", ""))
def test_blink_is_set(dut, blink):
    """Each blink code (steady, 1, 2, 5 Hz) is taken, answered and shown by 242."""
    colour, _ = _led(dut)
    _set(dut, NO_SAVE, colour, _other_blink(blink))
    ex = _set(dut, SAVE, colour, blink)
    _check_echo(ex, SAVE, colour, blink)
    assert not (d := _differs((colour, blink), _led(dut))), f"after Set Led blink {blink} 242 differs from what was set: {d} (set -> 242)"


@pytest.mark.requirement("4.4.20-3", "4.4.20-T", "4.4.28-1")
@pytest.mark.parametrize("value", HIGH_COLOURS, ids=lambda v: f"color{v:#04x}")
def test_only_the_low_three_bits_of_colour_count(dut, value):
    """'the lower 3Bit is valid': a colour byte with high bits set is taken by its low three bits."""
    want = value & COLOUR_MASK
    blink = BLINKS[1]
    _set(dut, NO_SAVE, _other_colour(want), blink)
    ex = _set(dut, NO_SAVE, value, blink)
    dut.record.observe("colour answered", ex.response.fields["color"] if ex.response else "none")
    _check_echo(ex, NO_SAVE, want, blink)
    assert not (d := _differs((want, blink), _led(dut))), (
        f"after colour {value:#04x}, low bits {want}, 242 differs from what was set: {d} (set -> 242)")


def _write_unsaved(dut):
    saved = _led(dut)
    _ensure(dut, SAVE, *saved)  # what the power cycle must bring back is saved
    colour, blink = _other_colour(saved[0]), _other_blink(saved[1])
    _set(dut, NO_SAVE, colour, blink)
    assert not (d := _differs((colour, blink), _led(dut))), f"option 0 did not update the LED at once: 242 differs from what was set: {d} (set -> 242)"
    return saved


@pytest.mark.requirement("4.4.20-2", "R13", "4.4.28-1")
@pytest.mark.power_cycle
@pytest.mark.cold_boot(_write_unsaved, touches="led")
def test_unsaved_setting_is_lost_at_power_off(dut, cold_boot):
    """Option 0: the LED changes at once, and after a power cycle the saved setting is back."""
    saved = cold_boot()
    assert not (d := _differs(saved, _led(dut))), f"after a power cycle 242 is not the saved setting: {d} (saved -> 242)"


def _write_saved(dut):
    before = _led(dut)
    colour, blink = _other_colour(before[0]), _other_blink(before[1])
    _set(dut, SAVE, colour, blink)
    assert not (d := _differs((colour, blink), _led(dut))), f"option 1 did not update the LED at once: 242 differs from what was set: {d} (set -> 242)"
    return colour, blink


@pytest.mark.requirement("4.4.20-2", "4.4.20-5", "R13", "4.4.28-1")
@pytest.mark.power_cycle
@pytest.mark.cold_boot(_write_saved, touches="led")
def test_saved_setting_survives_power_off(dut, cold_boot):
    """Option 1: the LED changes at once and is still so after a power cycle."""
    colour, blink = cold_boot()
    assert not (d := _differs((colour, blink), _led(dut))), f"after a power cycle 242 is not the saved setting: {d} (saved -> 242)"


@pytest.mark.requirement("4.4.20-6", "4.4.2-3", "R12", "4.4.28-1")
@pytest.mark.parametrize("option", [NO_SAVE, SAVE], ids=["no-save", "save"])
def test_not_set_while_reporting_is_suspended(dut, option):
    """Suspended by MSG Control, Set Led takes no effect (not even once reporting resumes). First shown
    to work with reporting on, so that a command that never works does not pass."""
    before = _led(dut)
    colour, blink = _other_colour(before[0]), _other_blink(before[1])
    _ensure(dut, option, colour, blink)
    _ensure(dut, option, *before)
    dut.suspend_reporting()
    try:
        ex = _set(dut, option, colour, blink)
        dut.record.observe("answer while suspended", ex.response.fields if ex.response else "none")
    finally:
        dut.resume_reporting()
    assert not (d := _differs(before, _led(dut))), f"Set Led while suspended took effect: 242 {d}"


@pytest.mark.requirement("4.4.20-4")
@pytest.mark.parametrize("blink", UNASSIGNED_BLINKS, ids=lambda b: f"blink{b:#04x}")
def test_observe_unassigned_blink_codes(dut, blink):
    """'other: No operation is performed, no blinking': what the DUT makes of it is recorded."""
    colour, before = _led(dut)
    if before == 0:
        _set(dut, NO_SAVE, colour, BLINKS[1])
        before = BLINKS[1]
    ex = _set(dut, NO_SAVE, colour, blink)
    after = _led(dut)[1]
    dut.record.observe(f"blink {blink:#04x}: answer", ex.response.fields if ex.response else "none")
    dut.record.observe(f"blink {blink:#04x}: 242 blink before -> after", f"{before} -> {after}")
    assert after == 0, f"blink code {blink:#04x}: 242 blink {after} (read as 'no blinking')"


@pytest.mark.requirement("4.4.20-4")
def test_observe_current_led_against_factory_default(dut):
    """Factory default: green, no blink (a DUT in the field may differ: recorded, never failed)."""
    colour, blink = _led(dut)
    dut.record.observe("LED colour, blink", (_name(colour), cat.LED_BLINK.get(blink, blink)))
    assert (colour, blink) == (COLOR.default, SPEC.request.field("blink").default), "not at the factory default"


@pytest.mark.requirement("4.4.20-7")
def test_observe_led_support(dut):
    """'only valid for ESC with LED': whether the DUT answers Set Led (the current setting, unsaved)."""
    colour, blink = _led(dut)
    ex = _set(dut, NO_SAVE, colour, blink)
    dut.record.observe("profile says LED", dut.profile.has("led"))
    dut.record.observe("answer to Set Led", ex.response.fields if ex.response else "none")
    assert ex.response is not None, "no answer to Set Led"


@pytest.mark.requirement("R13", "4.4.20-5", "4.4.21-4", "4.4.22-6", "4.4.23-4", "4.4.22-2", "4.4.28-1")
@pytest.mark.power_cycle
def test_save_leaves_the_other_settings(dut):
    """A saved LED rewrites nothing else: the other persisted settings, moved since this power-up, are as they were,
    at once and after a power cycle (a save rewriting a whole flash block can clobber them)."""
    with neighbours_moved(dut, but="led") as moved:
        colour, blink = _other_colour(moved["led_color"]), _other_blink(moved["led_blink"])
        _ensure(dut, SAVE, colour, blink)
        check_neighbours_kept(dut, moved, f"Set Led option 1 (color {colour}, blink {blink})",
                              {"led_color": colour, "led_blink": blink})
