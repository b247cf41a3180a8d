"""Spec section 4.4.9: MSG_EXP7 (20059) - the setting parameters, in MSG_EXP mode."""

from __future__ import annotations

import pytest

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat
from ckesc.protocol.catalogue import LedColor

from .telemetry import exp_reports

SECTION = "4.4.9"

LAYOUT = cat.spec("msg_exp7").layouts[0]
ROTATION = cat.spec("get_major_configuration").response.field("direction").codes
SOURCE = cat.spec("get_major_configuration").response.field("throttle_source").codes
#: (rotation, throttle source, LED colour) per case; the colours are the ones MSG_EXP7 can name
CASES = {
    "forward-CAN-green": (0, 0, LedColor.GREEN),
    "reverse-CAN-red": (1, 0, LedColor.RED),
    "forward-PWM+CAN-blue": (0, 1, LedColor.BLUE),
    "reverse-PWM+CAN-off": (1, 1, LedColor.OFF),
}


def _code(field: str, meaning: str) -> int:
    """The MSG_EXP7 code of a meaning ('reverse', 'PWM+CAN', 'red'); the tables spell some differently."""
    norm = meaning.lower().replace("+", "_")
    for code, name in LAYOUT.field(field).codes.items():
        if name.lower() == norm:
            return code
    raise KeyError(f"{field}: no code for {meaning!r}")


def _in_force(what: str, requested: int | None, *witnesses: int | None) -> int:
    """The setting in force: the value requested when the request's answer or 242 confirms it; without
    a request, 242's. Neither confirming: INCONCLUSIVE (which one to compare MSG_EXP7 with is unknown)."""
    if requested is None:
        return witnesses[-1]
    if requested in witnesses:
        return requested
    raise Inconclusive(f"{what} {requested} requested, but neither its answer nor 242 confirms it "
                       f"(they say {' and '.join(map(str, witnesses))})")


@pytest.mark.requirement("4.4.9-T")
@pytest.mark.parametrize("case", list(CASES))
def test_exp7_reports_the_settings(dut, case):
    """Direction (1 forward, 2 reverse), LED (0 off, 1 red, 2 green, 3 blue) and interface (2 PWM_CAN,
    3 CAN) are the settings in force; every other nibble holds a legal code."""
    rotation, source, color = CASES[case]
    answers = {"rotation": dut.ask("set_rotation", {"rotation": rotation})["rotation"],
               "source": dut.ask("throttle_select", {"source": source})["source"],
               "color": None}
    if dut.profile.has("led"):
        answers["color"] = dut.ask("set_led", {"option": 0, "color": int(color), "blink": 0})["color"]
    else:
        color = None
    s = dut.settings()
    in_force = {"rotation": _in_force("rotation", rotation, answers["rotation"], s["rotation"]),
                "source": _in_force("throttle source", source, answers["source"], s["throttle_source"]),
                "color": _in_force("LED colour", None if color is None else int(color), answers["color"], s["led_color"])}
    frames, _ = exp_reports(dut, "msg_exp7")
    dut.record.observe("settings in force", in_force)
    dut.record.observe("MSG_EXP7", frames[-1].physical())
    expected = {"direction": _code("direction", ROTATION[in_force["rotation"]]),
                "comm_interface": _code("comm_interface", SOURCE[in_force["source"]])}
    led = LedColor(in_force["color"])
    if led.name is not None and (led is LedColor.OFF or led.name.lower() in LAYOUT.field("led").codes.values()):
        expected["led"] = _code("led", led.name)  # mixtures (e.g. red+green) have no MSG_EXP7 code
    for f in frames:
        got = {k: f.fields[k] for k in expected}
        assert got == expected, f"MSG_EXP7 {got}, the settings in force {in_force} give {expected}"
        illegal = {fd.name: f.fields[fd.name] for fd in LAYOUT.fields
                   if (fd.codes is not None or fd.legal is not None) and not fd.is_legal(f.fields[fd.name])}
        assert not illegal, f"MSG_EXP7 nibbles outside the table: {illegal}"
