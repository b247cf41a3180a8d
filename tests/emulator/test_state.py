"""The ESC model's RAM is one explicit object, :class:`~ckesc.emulator.esc_state.EscState` (issue #28): its parts read
and write ``self.state.X``; a fresh one at each power-up; a RAM field set on the model itself fails, saying where it
went (a part that did so would keep a copy no other part reads)."""

from __future__ import annotations

import pytest

from ckesc.emulator.esc_state import FIELDS, EscState
from ckesc.emulator.model import EscConfig, EscModel


def test_a_power_up_starts_a_fresh_state():
    esc = EscModel(EscConfig(node_id=1))
    esc.power_on(0.0)
    first = esc.state
    first.led_color, first.reporting = 5, "suspended"  # an unsaved Set LED, a suspension: RAM only
    esc.power_off(1.0)
    esc.power_on(2.0)
    assert esc.state is not first and isinstance(esc.state, EscState)
    assert (esc.state.led_color, esc.state.reporting) == (esc.nvm["led_color"], "normal")
    assert esc.state.powered_at == 2.0 and esc.state.ready_at == 2.0 + esc.config.boot_time


@pytest.mark.parametrize("name, field", [("reporting", "reporting"), ("_next_report", "next_report"), ("bitrate", "bitrate")])
def test_the_ram_is_not_set_on_the_model(name, field):
    esc = EscModel()
    with pytest.raises(AttributeError, match=rf"self\.state\.{field}\b"):
        setattr(esc, name, 1)
    with pytest.raises(AttributeError, match=rf"self\.state\.{field}\b"):
        getattr(esc, name)
    with pytest.raises(AttributeError):
        esc.state.no_such_field = 1  # slotted: a field not named in EscState cannot be made by mistake
    assert field in FIELDS
