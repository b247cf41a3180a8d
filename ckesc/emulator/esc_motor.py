"""The motor side of an emulated ESC: the throttle it follows (RawCommand of each format, PWM), the motor and
its temperatures, the running counters, and the comm-loss flag (R8)."""

from __future__ import annotations

import math

from ..protocol.catalogue import COMM_LOSS_TIMEOUT_S, INTERVAL_UNIT_S, THROTTLE_10B_MAX, THROTTLE_MAX
from ..protocol.codecs import TAIL_BITS_10B, unpack_throttle12
from ..protocol.frame import Frame
from ..protocol.ids import Kind
from .config import RECORD_SENSORS
from .faults import WARM_CLOCK_RATE, onset

#: (sensor, time constant s, rise at full load degC, ambient degC): a plausible, not a measured, ESC.
_THERMAL = (("mos", 20.0, 60.0, 25.0), ("cap", 40.0, 35.0, 25.0), ("mcu", 30.0, 20.0, 30.0), ("motor", 60.0, 70.0, 25.0))

#: Faults that change which throttle frames address an ESC (see EscModel.throttle_keys).
_THROTTLE_READ_FAULTS = frozenset({"throttle_channel_ignored", "twelve_bit_nibbles_swapped", "twelve_bit_group_ignored",
                                   "fourteen_bit_byte_order"})


class Motor:
    """Part of :class:`~ckesc.emulator.model.EscModel`: throttle, motor, temperatures, comm loss."""

    def _update(self, now: float) -> None:
        dt = now - self.state.last_update
        if dt <= 0:
            # no time passed, but a deadline may have come due without it (Throttle Select back to CAN
            # long after the last command): without this the comm-loss deadline stays in the past and
            # the lane polls at the same instant for ever
            self._refresh_throttle(now)
            return
        self.state.last_update = now
        self._refresh_throttle(now)
        target = self.state.throttle / THROTTLE_MAX * self.config.max_rpm
        if target != self.state.rpm:  # (at the target it stays: a motor at rest, hours long, costs no exp)
            self.state.rpm += (target - self.state.rpm) * (1 - math.exp(-dt / self.config.motor_tau))
        if target == 0 and self.state.rpm < 1:
            self.state.rpm = 0.0
        load = self.state.rpm / self.config.max_rpm
        self.state.current = 80.0 * load**3
        thermal_dt = now - self.state.last_thermal
        if thermal_dt >= 0.05:  # temperatures move in seconds: a coarser step costs less
            self.state.last_thermal = now
            for name, tau, gain, ambient in _THERMAL:
                goal = ambient + gain * load**2
                self.state.temps[name] += (goal - self.state.temps[name]) * (1 - math.exp(-thermal_dt / tau))
            self._record_temperatures()
        running = self.state.rpm >= 1 or self.state.throttle > 0
        if running:
            if now > self.state.warm_at and "clock_drift_warm" in self.faults:  # seconds of a fast clock
                dt *= WARM_CLOCK_RATE
            self.state.run_time += dt
            self.nvm["total_run_time"] += dt
        if running != self.state.running:
            self.state.running = running
            key = "starts" if running else "stops"
            self.nvm[key] = (self.nvm[key] + 1) & 0xFFFF
            self.nvm_dirty = True

    def _record_temperatures(self) -> None:
        for sensor in RECORD_SENSORS:
            t = self._whole(self.state.temps[sensor])
            rec = self.nvm["records"][sensor]
            if t > rec["t_max"]:
                rec.update(t_max=min(t, 255), times=self.nvm["starts"], time=self._whole(self.nvm["total_run_time"]))
                self.nvm_dirty = True

    def _active_source_is_pwm(self) -> bool:
        return self.nvm["throttle_source"] == 1 and self.pwm_input is not None

    def _refresh_throttle(self, now: float) -> None:
        if self._active_source_is_pwm():
            self.state.throttle = min(max(self.pwm_input or 0, 0), THROTTLE_MAX)
            self.state.comm_fault = False
            self.state.pwm_seen = True
            return
        if self._comm_loss_due(now):
            self.state.comm_fault = True
            self.state.can_throttle = 0  # lost-signal protection: throttle to zero
        self.state.throttle = self.state.can_throttle
        if "pwm_no_fallback" in self.faults and self.state.pwm_seen and self.nvm["throttle_source"] == 1:
            self.state.throttle = 0  # the lost PWM signal is not replaced by the CAN throttle

    def _comm_loss_timeout(self) -> float | None:
        if "comm_loss_never" in self.faults:
            return None
        if "comm_loss_late" in self.faults:
            return 0.400
        if "comm_loss_early" in self.faults:
            return 0.100
        return COMM_LOSS_TIMEOUT_S

    def _comm_loss_deadline(self) -> float | None:
        if self.state.comm_fault or self._active_source_is_pwm():
            return None
        timeout = self._comm_loss_timeout()
        if timeout is None:
            return None
        since = self.state.last_command if self.state.last_command is not None else self.state.ready_at
        deadline = since + timeout
        check = self.config.comm_loss_check
        if check == "timer" or not self._reports_active() or "msg1" not in self.state.next_report:
            return deadline
        # checked on MSG1's grid (each MSG1 due) or on the report timer's 2 ms tick through it: the first
        # point of it at or after the deadline
        period = self._interval("msg1") if check == "msg1" else INTERVAL_UNIT_S
        grid = self.state.next_report["msg1"]
        if period <= 0:
            return deadline
        if check == "msg1" and self.state.offset:  # checked when the jittered MSG1 goes out (exactly then: no rounding)
            grid = self._jittered("msg1")
            return grid + max(0, math.ceil(round((deadline - grid) / period, 9))) * period
        return round(grid + math.ceil(round((deadline - grid) / period, 9)) * period, 9)

    def _comm_loss_due(self, now: float) -> bool:
        deadline = self._comm_loss_deadline()
        return deadline is not None and now >= deadline

    def _over_max(self, maximum: int) -> int:
        """R6 (OBSERVE): a throttle above its maximum clamped, taken as zero, or (-1) ignored for the held one."""
        how = self.config.over_max_throttle
        return maximum if how == "clamp" else 0 if how == "zero" else -1

    def throttle_keys(self) -> set[tuple[str, int | None]] | None:
        """The throttle frames this ESC can be addressed by, as (frame name, 12-bit group or None);
        None: all of them (a fault changes how it reads them). Lets a bench route throttle frames
        to the ESCs they concern; must agree with :meth:`_on_throttle`."""
        if self.faults & _THROTTLE_READ_FAULTS:
            return None
        ch = self.nvm["throttle_channel"]
        keys: set[tuple[str, int | None]] = {("raw_command_12b", (ch + 3) // 4)}
        if 1 <= ch <= 4:
            keys.add(("raw_command_14b", None))
        if 1 <= ch <= 6:
            keys.add(("raw_command_10b", None))
        return keys

    def _on_throttle(self, f: Frame, now: float) -> None:
        channel = 1 if "throttle_channel_ignored" in self.faults else self.nvm["throttle_channel"]
        name = f.spec.name  # (a handled frame's spec is known)
        value: int | None = None
        if name == "raw_command_14b":
            channels = f.fields["channels"]
            if "fourteen_bit_byte_order" in self.faults:
                v = int.from_bytes(f.data[:7], "little")
                channels = [(v >> (14 * i)) & 0x3FFF for i in range(4)]
            if 1 <= channel <= 4:
                value = channels[channel - 1]
        elif name == "raw_command_12b":
            channels, group = f.fields["channels"], f.fields["group"]
            if "twelve_bit_nibbles_swapped" in self.faults:
                channels, group = unpack_throttle12(f.data[:7], nibble_order="swapped")
            if "twelve_bit_group_ignored" in self.faults:
                value = channels[(channel - 1) % 4]
            elif 4 * group - 3 <= channel <= 4 * group:
                value = channels[channel - 4 * group + 3]
        else:  # raw_command_10b
            if self.state.selected and "throttle_select_drops_10b" in self.faults:
                return False  # the parser table rebuilt without the 10-bit format
            if "ten_bit_tail_checked" in self.faults and f.fields["tail_bits"] != TAIL_BITS_10B:
                return False  # the high nibble of payload[7] read as a tail byte, and this one refused
            if 1 <= channel <= 6:
                raw = f.fields["channels"][channel - 1]
                if raw > THROTTLE_10B_MAX:
                    raw = self._over_max(THROTTLE_10B_MAX)
                value = raw if "ten_bit_not_doubled" in self.faults or raw < 0 else raw * 2
        if value is None:
            return False  # not addressed to this ESC's channel: not a command for it
        if "reset_after_streaming" in self.faults and self._stream_resets(now):
            return True  # the frame's handling hung: the watchdog restarted the ESC (it boots, then hears again)
        if value > THROTTLE_MAX:
            value = self._over_max(THROTTLE_MAX)
        if value < 0:  # over_max_throttle "hold": the frame's value ignored, the command still heard
            value = self.state.can_throttle
        answered = "throttle_answered" in self.faults
        if answered:  # the broadcast taken for a request: a report at once, as its answer
            self._emit_report("msg1", now + self.config.service_delay)
        if value == self.state.can_throttle and not self.state.comm_fault:
            # the same command again: only the comm-loss deadline moves, and later, so nothing is due
            # earlier than before; the motor's first-order lag integrates exactly over the longer step
            self.state.last_command = now
            return answered  # an answer was queued: the ESC's next deadline moved
        self._update(now)
        self.state.can_throttle = value  # R6: above 2000 is OBSERVE (over_max_throttle)
        self.state.last_command = now
        if self.state.comm_fault and not self._comm_flag_sticks():
            self.state.comm_fault = False
        self._refresh_throttle(now)

    def _comm_flag_sticks(self) -> bool:
        """Whether a command leaves the comm-loss flag set (faults comm_loss_sticky, comm_loss_sticky_after_resume)."""
        return "comm_loss_sticky" in self.faults or (self.state.resumed and "comm_loss_sticky_after_resume" in self.faults)

    def _keep_alive(self, f: Frame, now: float) -> bool:
        """Fault 'comm_watchdog_kept_alive': a request addressed to this ESC or a GET_ESC_ID query refreshes the comm
        watchdog as a command does (R20: only RawCommand may), the throttle unchanged. True when it did."""
        if not (f.kind is Kind.REQUEST and f.destination == self.node_id
                or f.name == "get_esc_id" and f.layout is not None and f.layout.name == "query"):
            return False
        self._update(now)
        self.state.last_command = now
        if self.state.comm_fault and not self._comm_flag_sticks():
            self.state.comm_fault = False
        return True

    def _stream_resets(self, now: float) -> bool:
        """Fault 'reset_after_streaming': a command addressed to this ESC continues the stream (no gap longer than
        the comm-loss time since the last) or starts one; once the stream has run its onset without a break, the
        watchdog resets the ESC (a power-up: what flash holds is kept, RAM is not). True when it reset."""
        last = self.state.last_command
        if self.state.stream_since is None or last is None or now - last > COMM_LOSS_TIMEOUT_S:
            self.state.stream_since = now
            return False
        if now - self.state.stream_since < onset("reset_after_streaming", self.config.onsets):
            return False
        self.power_off(now)
        self.power_on(now)
        return True

    def this_run_time(self) -> float:
        """This run's running time in seconds as 241 option 1 and MSG_EXP10 report it (fault 'run_time_wraps': kept
        in a uint16 of 50 ms ticks, so modulo 65536 ticks, or the onset given)."""
        if "run_time_wraps" in self.faults:
            return self.state.run_time % onset("run_time_wraps", self.config.onsets)
        return self.state.run_time

    def _motor_busy(self) -> bool:
        return (self.state.running or self.state.throttle > 0) and "rotation_while_running" not in self.faults
