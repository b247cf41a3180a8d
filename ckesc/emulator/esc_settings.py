"""The settings an emulated ESC keeps in flash (R13) and the requests that write them: Set ID and Set Baud (the
120 s window, R11), Set LED, Set Rotation, Set Freq, Throttle Select, Expand Set Part; none while reporting is
suspended (R12), illegal values ignored (R10)."""

from __future__ import annotations

from typing import Any

from ..protocol import catalogue as cat
from ..protocol.catalogue import BAUD_RATES, CONFIG_WINDOW_S, EXPAND_COMMANDS, INTERVAL_UNIT_S
from ..protocol.frame import Frame
from .config import factory_nvm
from .esc_telemetry import REPORT_NAMES, SUSPENDED

#: fault destination_low_bits: the bits of a destination node id it decodes
_LOW_SIX = 0x3F


class Settings:
    """Part of :class:`~ckesc.emulator.model.EscModel`: the requests that write settings."""

    def _addressed(self, f: Frame) -> bool:
        if "destination_low_bits" in self.faults:  # a destination decoded from its low six bits only
            return (f.destination or 0) & _LOW_SIX == self.node_id & _LOW_SIX
        return f.destination == self.node_id

    def _settings_locked(self, fault: str = "") -> bool:
        """R12: parameter changes do not take effect while reporting is suspended (unless ``fault``, the request's
        own fault of taking it then, or ``settings_while_suspended`` is on)."""
        return self.state.reporting == SUSPENDED and "settings_while_suspended" not in self.faults and fault not in self.faults

    def _in_window(self, now: float, fault: str) -> bool:
        window = CONFIG_WINDOW_S / 2 if "config_window_short" in self.faults else CONFIG_WINDOW_S
        return now - self.state.powered_at <= window or fault in self.faults

    def _set_nvm(self, **values: Any) -> None:
        self.nvm.update(values)
        self.nvm_dirty = True
        for key in values:  # its own save puts a clobbered setting right again
            self.state.flash_only.pop(key, None)

    def _clobber(self, fault: str, **stale: Any) -> None:
        """An interaction fault's save that also rewrites other settings in flash with ``stale`` values (the RAM
        copies stay: the ESC works on with them until the next power-up)."""
        if fault in self.faults:
            self.state.flash_only.update(stale)

    def _on_set_id(self, f: Frame, now: float) -> None:
        if "set_id_needs_destination" in self.faults and not self._addressed(f):
            return
        node, channel = f.fields["node_id"], f.fields["throttle_channel"]
        legal = 1 <= node <= 0x7D or ("set_id_accepts_illegal" in self.faults and node <= 0x7F)
        legal = legal and 1 <= channel <= 20
        current = {"node_id": self.node_id, "throttle_channel": self.nvm["throttle_channel"]}
        if not (legal and self._in_window(now, "set_id_after_window") and not self._settings_locked("set_id_while_suspended")):
            self._respond_rejected(f, now, current)
            return
        if "set_id_channel_ignored" in self.faults:
            channel = self.nvm["throttle_channel"]
        self._set_nvm(node_id=node, throttle_channel=channel)
        if "set_id_resets_source" in self.faults:
            self._set_nvm(throttle_source=0)
        self._respond(f, now, {"node_id": self.node_id, "throttle_channel": self.nvm["throttle_channel"]})

    def _on_set_baud(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        code = f.fields["baud"]
        legal = code in BAUD_RATES or "set_baud_accepts_illegal" in self.faults
        if not (legal and self._in_window(now, "set_baud_after_window")
                and not self._settings_locked("set_baud_while_suspended")):
            self._respond_rejected(f, now, {"baud": self.nvm["baud"]})
            return
        self._set_nvm(baud=code)
        if "set_baud_immediate" in self.faults:
            self.state.bitrate = BAUD_RATES.get(code, self.state.bitrate)
        self._respond(f, now, {"baud": self.nvm["baud"]})

    def _on_set_led(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        option, color, blink = f.fields["option"], f.fields["color"], f.fields["blink"]
        no_operation = blink not in cat.LED_BLINK and self.config.led_blink_other == "no_operation"
        if option in (0, 1) and self._settings_locked():  # R12: refused, and its answer free like every refusal's
            self._respond_rejected(f, now, {"option": option, "color": self.state.led_color, "blink": self.state.led_blink})
            return
        if self.config.has_led and option in (0, 1) and not self._settings_locked() and not no_operation:
            color &= 0x07  # "the lower three bits of Color are valid"
            blink = blink if blink in cat.LED_BLINK else 0  # "other: no operation is performed, no blinking"
            self.state.led_color, self.state.led_blink = color, blink
            if option == 1 or "led_unsaved_persisted" in self.faults:
                self._set_nvm(led_color=color, led_blink=blink)
            if option == 1:
                self._clobber("led_save_reverts_rotation", rotation=self.state.boot["rotation"])
        if "set_led_no_echo" in self.faults:
            self._respond(f, now, {"option": 0, "color": 0, "blink": 0})
            return
        self._respond(f, now, {"option": option, "color": self.state.led_color, "blink": self.state.led_blink})

    def _on_set_rotation(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        rotation = f.fields["rotation"]
        if rotation != 0xFF and not self._settings_locked() and not self._motor_busy():
            if rotation in (0, 1):
                if "rotation_ignored" not in self.faults:
                    self._set_nvm(rotation=rotation)
                    self._clobber("rotation_save_resets_intervals", **cat.DEFAULT_REPORT_INTERVALS)
            elif "rotation_accepts_illegal" in self.faults:
                self._set_nvm(rotation=1)
            else:
                self._respond_rejected(f, now, {"rotation": self.nvm["rotation"]})
                return
        elif rotation != 0xFF:
            self._respond_rejected(f, now, {"rotation": self.nvm["rotation"]})
            return
        self._respond(f, now, {"rotation": self.nvm["rotation"]})

    def _on_set_freq(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        names = cat.INTERVAL_FIELDS
        lo, hi = cat.REPORT_INTERVAL_RANGE
        applied = f.fields["option"] != 1
        if f.fields["option"] == 1 and not self._settings_locked():
            values = {k: f.fields[k] for k in names}
            legal = {k: v for k, v in values.items() if lo <= v <= hi}
            if "set_freq_accepts_illegal" in self.faults:
                legal = {k: v for k, v in values.items() if v > 0}
            if len(legal) == 3 or ("set_freq_partial" in self.faults and legal):
                applied = True
                old = {k: self.nvm[k] for k in names}
                self._set_nvm(**legal)
                defaults = factory_nvm(self.config)
                self._clobber("freq_save_resets_led", led_color=defaults["led_color"], led_blink=defaults["led_blink"])
                self.state.default_timers = False  # a write reloads the report timers
                if "set_freq_moves_other_stream" in self.faults:
                    if legal.get("msg2_interval", old["msg2_interval"]) != old["msg2_interval"]:
                        self.state.timer_from.pop("msg2", None)
                    elif legal.get("msg1_interval", old["msg1_interval"]) != old["msg1_interval"]:
                        self.state.timer_from["msg2"] = "msg1"
                for which in REPORT_NAMES:
                    key = f"{which}_interval"
                    if key in legal and legal[key] != old[key]:
                        self.state.next_report[which] = self._set_freq_next(which, now, old[key] * INTERVAL_UNIT_S)
        current = {k: self.nvm[k] for k in names}
        if "set_freq_read_wrong" in self.faults and f.fields["option"] == 0:
            current = dict(cat.DEFAULT_REPORT_INTERVALS)
        if not applied:
            self._respond_rejected(f, now, {"option": f.fields["option"], **current})
            return
        self._respond(f, now, {"option": f.fields["option"], **current})

    def _on_throttle_select(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        source = f.fields["source"]
        legal = source in (0, 1) or "throttle_select_accepts_illegal" in self.faults
        if not (legal and not self._settings_locked() and not self._motor_busy()):
            self._respond_rejected(f, now, {"source": self.nvm["throttle_source"]})
            return
        if "throttle_select_ignored" not in self.faults:
            self._set_nvm(throttle_source=source)
            self._clobber("source_save_reverts_led", led_color=self.state.boot["led_color"], led_blink=self.state.boot["led_blink"])
        self.state.selected = True
        self._respond(f, now, {"source": self.nvm["throttle_source"]})


    def _on_expand_set(self, f: Frame, now: float) -> None:
        if not self._addressed(f) or "expand_set_part_absent" in self.faults:
            return
        code, part = f.fields["set_cmd"], f.fields["part"]
        if "expand_set_big_endian" in self.faults:
            code = int.from_bytes(f.data[:2], "big")
        if "expand_set_answered" in self.faults:  # the catalogue has no response layout (R14): echo the request
            self._echo_request(f, now)
        command = EXPAND_COMMANDS.get(code)
        if command is None or part not in command.parts or command.reserved:
            self.counters["rx_ignored"] += 1
            return
        if command.name == "read_temperature_records":
            self._send_records(now)
            return
        if command.name == "maintenance":
            self.state.test_mode = part == 0x11 if part in (0x10, 0x11) else self.state.test_mode
            return
        if self._settings_locked() or self._motor_busy():
            return  # 4.4.25 clarification 1: motor stopped; R12
        n = command.name
        if n == "direction":
            self._set_nvm(rotation=part - 1)
        elif n == "led":
            self.state.led_color = {0: 0, 1: 4, 2: 2, 3: 1}[part]
            self._set_nvm(led_color=self.state.led_color)
        elif n == "control_mode":
            if part in (2, 5):
                self._set_nvm(throttle_source=1)
            elif part in (3, 6):
                self._set_nvm(throttle_source=0)
        elif n == "active_freewheel":
            self._set_nvm(active_freewheel=part)
        elif n == "prop_lock":
            self._set_nvm(prop_lock=part)
        elif n == "startup_acceleration":
            self._set_nvm(startup_acceleration=part)
        elif n == "lost_signal_reduction":
            self._set_nvm(lost_signal_reduction=part)
        elif n == "baud":
            self._set_nvm(baud=part)
