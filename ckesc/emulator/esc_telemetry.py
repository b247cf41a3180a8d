"""What an emulated ESC reports on its own: MSG1..3 and MSG_EXP streams, their timers (R9, R9a), the reporting
modes MSG Control switches (suspend, resume, MSG_EXP mode: 4.4.2) and CAN Test mode (R16)."""

from __future__ import annotations

import math

from ..protocol import catalogue as cat
from ..protocol.catalogue import (
    CAN_TEST_OFF,
    CAN_TEST_ON,
    COMM_LOSS_TIMEOUT_S,
    INTERVAL_UNIT_S,
    MSG_CONTROL_RESUME,
    MSG_CONTROL_RESUME_EXP,
    MSG_CONTROL_SUSPEND,
    Status,
)
from ..protocol.codecs import codec_for
from ..protocol.frame import Frame, WireFrame, frame_bits
from ..protocol.ids import DEFAULT_ESC_NODE_ID, Priority, message_id
from ..protocol.transfer import tail_byte
from .esc_state import EXP_MODE, REPORTING, SUSPENDED  # the reporting states (MSG Control, 4.4.2)
from .faults import GLITCH_EVERY_S, WARM_CLOCK_RATE
from .variants import ABOVE_HALF_SHARE, ABOVE_HALF_WINDOW_S

REPORT_NAMES = cat.REPORT_FRAMES
#: fault drops_reports_under_load: a report due when foreign frames (types it does not know) took more than this
#: share of the bus in the window before it is skipped (an ESC without hardware filters: its receive interrupt
#: drops each such frame in software, and a busy bus starves the loop that sends the reports)
_FOREIGN_SHARE = 1 / 3
_FOREIGN_WINDOW_S = 0.010

_PWM, _CCW, _COMM_FAULT, _RUNNING = (int(Status.THROTTLE_PWM), int(Status.DIRECTION_CCW), int(Status.COMM_FAULT),
                                     int(Status.RUNNING))


#: the settings key of each report's interval
_INTERVAL_KEYS = {name: f"{name}_interval" for name in REPORT_NAMES}


class Telemetry:
    """Part of :class:`~ckesc.emulator.model.EscModel`: the report streams and their timers."""

    def _reports_active(self) -> bool:
        if self.state.can_test and "can_test_reports_continue" not in self.faults:
            return False
        if self.node_id == DEFAULT_ESC_NODE_ID and "reports_at_default_id" not in self.faults:
            return False  # F7: silent at 0x7D
        return self.state.reporting != SUSPENDED

    def _interval(self, which: str) -> float:
        n = self.nvm[_INTERVAL_KEYS.get(which) or f"{which}_interval"]
        if self.state.default_timers:  # interaction faults (faults.INTERACTION): a timer reloaded with the wrong value
            n = cat.DEFAULT_REPORT_INTERVALS[f"{which}_interval"]
        elif self.state.timer_from:
            n = self.nvm[f"{self.state.timer_from.get(which, which)}_interval"]
        if which == "msg2" and "msg2_interval_ignores_setting" in self.faults:
            n = cat.DEFAULT_REPORT_INTERVALS["msg2_interval"]
        unit = 0.003 if which == "msg1" and "report_interval_wrong" in self.faults else INTERVAL_UNIT_S
        period = n * unit
        if self.state.last_update > self.state.warm_at and "clock_drift_warm" in self.faults:
            period /= WARM_CLOCK_RATE  # a warm board's fast clock: the report timer's 2 ms ticks come sooner
        if "report_jitter" in self.faults:
            period *= 1 + self._rng.uniform(-0.3, 0.3)
        return period

    def _restart_reports(self, now: float) -> None:
        """Reporting comes back (a resume, leaving CAN Test or MSG_EXP mode; R9a: the first report of each type
        within one interval plus a slack), as ``report_timer`` says: the first report at once, then every interval
        from it ("restart") or on the grid the timer kept ("grid"); the first at the kept grid's next point
        ("next_tick"); or one full interval after the event ("one_interval"). With the fault 'report_restart_late',
        one and a half intervals after the event."""
        self.state.regrid = {}
        self.state.report_floor = now
        timer = self.config.report_timer
        for k, due in self.state.next_report.items():
            period = self._interval(k)
            if "report_restart_late" in self.faults:
                self.state.next_report[k] = round(now + 1.5 * period, 9)
            elif timer == "one_interval":
                self.state.next_report[k] = round(now + period, 9)
            elif timer in ("grid", "next_tick") and period > 0:
                due = self._grid_point(due, now, period)
                self.state.next_report[k] = now if timer == "grid" else due
                if timer == "grid" and due > now:
                    self.state.regrid[k] = due
            else:
                self.state.next_report[k] = now

    @staticmethod
    def _grid_point(due: float, now: float, period: float) -> float:
        """The next point at or after ``now`` of the grid through ``due`` with spacing ``period``."""
        if due >= now:
            return due
        return round(due + math.ceil(round((now - due) / period, 9)) * period, 9)

    def _jittered(self, which: str) -> float:
        """When ``which`` goes out next with jitter: its grid point plus its offset, never before the event that set
        its timer nor before its own previous report (a report the old grid brings close behind one sent at once)."""
        return max(self.state.next_report[which] + self.state.offset[which], self.state.report_floor,
                   self.state.last_jittered.get(which, -math.inf))

    def _jitter(self) -> float:
        """A report's offset from its grid point (report_jitter_s: within +- half of it)."""
        half = self.config.report_jitter_s / 2
        return self._rng.uniform(-half, half)

    def _next_report_times(self) -> list[float]:
        if self.state.offset:
            return [self._jittered(k) for k in self.state.next_report]
        return list(self.state.next_report.values())

    def _schedule_reports(self, now: float) -> None:
        if self.state.can_test:
            while self.state.next_can_test <= now:
                self._emit_can_test(self.state.next_can_test)
                self.state.next_can_test = round(self.state.next_can_test + self._interval("msg1"), 9)
        if not self._reports_active():
            self.state.reports_were_active = False
            return
        if not self.state.reports_were_active:  # leaving 0x7D, suspension or CAN Test: start afresh, no catch-up burst
            self.state.reports_were_active = True
            for k in self.state.next_report:  # (a resume or CAN Test off has set it already: _restart_reports)
                if self.state.next_report[k] < now:
                    self.state.next_report[k] = self.state.report_floor = now
        offset = self.state.offset
        next_report = self.state.next_report
        for which in REPORT_NAMES:
            if not offset and next_report[which] > now:  # (the hot path: a report not due yet)
                continue
            while (grid := next_report[which]) + (offset[which] if offset else 0.0) <= now:
                if offset:  # jitter: off the grid point by its offset (see _jittered)
                    self._emit_report(which, due := self._jittered(which))
                    self.state.last_jittered[which] = due
                    offset[which] = self._jitter()
                else:
                    self._emit_report(which, grid)
                next_report[which] = self.state.regrid.pop(which, None) or round(grid + self._interval(which), 9)  # no float drift

    # ------------------------------------------------------------------------------------------
    # reports

    def status_word(self) -> int:
        """MSG1 status (R7), with plain ints: IntFlag arithmetic is slow on this hot path."""
        s = cat.FAULT_CODE_STATUS_BITS.get(self.state.self_test_fault, 0)
        if self.nvm["rotation"]:
            s |= _PWM if "status_direction_bit14" in self.faults else _CCW
        if self._active_source_is_pwm() and "status_direction_bit14" not in self.faults:
            s |= _PWM
        if self.state.comm_fault:
            s |= _COMM_FAULT
        if self.state.running and "status_running_wrong" not in self.faults:
            s |= _RUNNING
        return s

    def _heard_foreign(self, msg, now: float) -> None:
        """Fault drops_reports_under_load: note a foreign frame heard (its end, its time on the bus)."""
        self.state.foreign.append((now, frame_bits(len(msg.data)) / self.state.bitrate))
        while self.state.foreign and self.state.foreign[0][0] < now - max(_FOREIGN_WINDOW_S, ABOVE_HALF_WINDOW_S):
            self.state.foreign.popleft()

    def _starved(self, due: float, share: float = _FOREIGN_SHARE, window: float = _FOREIGN_WINDOW_S) -> bool:
        """Fault drops_reports_under_load: whether foreign frames took more than ``share`` of the bus in the
        ``window`` before ``due`` (the receive interrupt's software filter starves the loop); the variant
        above_half_load=drop asks it of :data:`ABOVE_HALF_SHARE` over :data:`ABOVE_HALF_WINDOW_S`."""
        busy = sum(d for t, d in self.state.foreign if due - window <= t <= due)
        return busy > share * window

    def _emit_report(self, which: str, due: float) -> None:
        prio = Priority.MEDIUM if "wrong_priority" in self.faults else None
        if self.state.reporting == EXP_MODE:
            self._emit_exp(which, due)
            return
        if "drops_reports_under_load" in self.faults and self._starved(due):
            return  # never built: its transfer id is not counted either
        if self.config.above_half_load == "drop" and self._starved(due, ABOVE_HALF_SHARE, ABOVE_HALF_WINDOW_S):
            return  # (the variant: likewise)
        if which == "msg1":
            pwm = 0 if "speed_ignores_throttle" in self.faults else self.state.throttle
            status = self.status_word()
            if due >= self.state.glitch_at and "comm_flag_glitch" in self.faults:
                status |= self._comm_glitch(due)
            fields = {"speed": int(self.state.rpm), "pwm": pwm, "status": status}
        elif which == "msg2":
            volts, amps = self._electrical()
            scale = 10 if "msg2_scale_tenths" in self.faults else 100
            fine, whole = self._fine, self._whole
            fields = {"voltage": fine(volts * scale), "current": fine(amps * scale), "temperature": whole(self.state.temps["mos"])}
        if which in ("msg1", "msg2"):
            if "reports_padded" in self.faults:  # the payload zero-padded to 7 bytes: a full 8-byte frame
                spec = cat.BY_NAME[which]
                self._emit_raw(due, spec.type_id, codec_for(spec.layouts[0]).encode(fields).ljust(7, b"\0"), prio or Priority.LOWEST)
            else:
                self._emit(due, which, fields, priority=prio)
        else:
            whole = self._whole
            fields = {"mos_t": whole(self.state.temps["mos"]), "cap_t": whole(self.state.temps["cap"]),
                      "motor_t": whole(self.state.temps["motor"]) if self.config.has_motor_sensor else 0,
                      "mcu_t": whole(self.state.temps["mcu"])}
            if "msg3_short" in self.faults:
                self._emit_raw(due, 20052, bytes([fields["mos_t"], fields["cap_t"], fields["motor_t"]]), prio or Priority.LOWEST)
                return
            self._emit(due, "msg3", fields, priority=prio)

    def _comm_glitch(self, due: float) -> int:
        """Fault 'comm_flag_glitch': the comm-loss bit for the first MSG1 due at or after a glitch time (its onset
        after power-up, then every GLITCH_EVERY_S) while the command stream runs (a command within the comm-loss
        time, the flag not set for real); a glitch time that finds no stream passes without one."""
        while self.state.glitch_at <= due:
            self.state.glitch_at += GLITCH_EVERY_S
        last = self.state.last_command
        streaming = (last is not None and due - last <= COMM_LOSS_TIMEOUT_S and not self.state.comm_fault
                     and not self._active_source_is_pwm())
        return _COMM_FAULT if streaming else 0

    def _electrical(self) -> tuple[float, float]:
        sag = 0.02 * self.state.current
        noise = self._rng.uniform(-0.02, 0.02)
        return max(self.config.supply_voltage - sag + noise, 0.0), max(self.state.current + (noise if self.state.current else 0), 0.0)

    def _emit_exp(self, which: str, due: float) -> None:
        """MSG_EXP mode (R9: which frames and how often is OBSERVE): EXP1 at MSG1's interval,
        EXP7..EXP11 at MSG3's (or all at MSG2's, or one of the two only: exp_frames)."""
        plays = self.config.exp_frames
        if which == ("msg2" if plays == "msg2" else "msg1") and plays != "no_exp1":
            volts, amps = self._electrical()
            scale = 10 if "exp1_scale_tenths" in self.faults else 100
            self._emit(due, "msg_exp1", {"speed": int(self.state.rpm), "voltage": self._fine(volts * scale),
                                         "current": self._fine(amps * scale)})
        if which == ("msg2" if plays == "msg2" else "msg3") and plays != "exp1_only":
            for name, fields in self.exp_frames():
                self._emit(due, name, fields)
            if "debug_frames_reserved_source" in self.faults:  # F7: a debug frame from a hard-coded node id
                spec = cat.BY_NAME["msg_exp2"]
                data = bytes(spec.layouts[0].size) + bytes((tail_byte(self.state.tids.next(spec.name)),))
                self._push(due, WireFrame(message_id(spec.priority, spec.type_id, 0x7F), data, due))

    def exp_frames(self) -> list[tuple[str, dict]]:
        n = self.nvm
        led_code = {0: 0, 4: 1, 2: 2, 1: 3}.get(self.state.led_color, 0)
        direction = (2 if n["rotation"] else 1) - ("exp7_direction_zero_based" in self.faults)
        power_ups = (n["power_ups"] - ("exp8_power_ups_from_zero" in self.faults)) & 0xFFFF
        unit = 1000 if "exp_run_times_ms" in self.faults else 1  # seconds, or milliseconds
        whole = self._whole
        temps = {k: whole(v) for k, v in self.state.temps.items()}
        if not self.config.has_motor_sensor:
            temps["motor"] = 0
        exp11 = (temps["mos"], temps["mcu"], temps["cap"], temps["motor"])
        if "exp11_msg3_order" in self.faults:
            exp11 = (temps["mos"], temps["cap"], temps["motor"], temps["mcu"])
        return [
            ("msg_exp7", {"direction": direction, "led": led_code,
                          "comm_interface": 2 if n["throttle_source"] else 3, "active_freewheel": n["active_freewheel"],
                          "prop_lock": n["prop_lock"], "startup_acceleration": n["startup_acceleration"],
                          "lost_signal_protection": n["lost_signal_reduction"]}),
            ("msg_exp8", {"power_ups": power_ups, "starts": n["starts"], "stops": n["stops"]}),
            ("msg_exp9", {"total_run_time": whole(n["total_run_time"] * unit) & 0xFFFFFFFF,
                          "fault_code_1": self.state.self_test_fault}),
            ("msg_exp10", {"run_time": whole(self.this_run_time() * unit) & 0xFFFFFFFF, "fault_code_2": 0}),
            ("msg_exp11", dict(zip(("mos_t", "mcu_t", "cap_t", "motor_t"), exp11))),
        ]

    def _emit_can_test(self, due: float) -> None:
        self._emit(due, "can_test", {"option": 0x00, "count": self.state.can_test_count})
        step = 2 if "can_test_count_skips" in self.faults else 1
        self.state.can_test_count = (self.state.can_test_count + step) & 0xFFFFFFFF

    # ------------------------------------------------------------------------------------------
    # broadcast commands

    def _on_can_test(self, f: Frame, now: float) -> None:
        option = f.fields["option"]
        if option == CAN_TEST_ON and not self.state.can_test:
            self.state.can_test = True
            if self.config.can_test_count == "zero_each_session":
                self.state.can_test_count = 0
            self.state.next_can_test = now
        elif option == CAN_TEST_OFF and self.state.can_test and "can_test_off_ignored" not in self.faults:
            self.state.can_test = False  # R16: back to the state before; reporting state was kept
            if "can_test_off_resumes_reporting" in self.faults:
                self.state.reporting = REPORTING
            self._restart_reports(now)

    def _on_msg_control(self, f: Frame, now: float) -> None:
        if f.fields["option"] != 0:
            self.counters["rx_ignored"] += 1
            return
        command = f.fields["command"]
        was = self.state.reporting
        if command == MSG_CONTROL_SUSPEND and "suspend_ignored" not in self.faults:
            self.state.suspends += was == SUSPENDED and "second_suspend_latches" in self.faults
            self.state.reporting = SUSPENDED
        elif command == MSG_CONTROL_RESUME and "resume_ignored" not in self.faults:
            if self.state.suspends and was == SUSPENDED:
                self.state.suspends -= 1  # a nested suspend's resume: still suspended
            else:
                self.state.reporting = REPORTING
        elif command == MSG_CONTROL_RESUME_EXP:
            if "resume_exp_ignored" not in self.faults:
                self.state.reporting = EXP_MODE
        elif command not in (MSG_CONTROL_SUSPEND, MSG_CONTROL_RESUME):
            self.counters["rx_ignored"] += 1
            return  # the answer packet (0) or an unknown command: nothing to do
        if self.state.reporting != SUSPENDED:
            self.state.suspends = 0
        if was == SUSPENDED and self.state.reporting != SUSPENDED:
            self.state.resumed = True
            if command == MSG_CONTROL_RESUME and "resume_reloads_default_intervals" in self.faults:
                self.state.default_timers = True
            self._restart_reports(now)  # "immediate recovery"
        elif was == EXP_MODE and self.state.reporting == REPORTING:
            self._restart_reports(now)  # leaving MSG_EXP mode: reporting comes back as after a resume (R9a)
        if "msg_control_no_answer" in self.faults:
            return
        answer = command if "msg_control_answer_echo" in self.faults else cat.MSG_CONTROL_ANSWER
        self._emit(now + self._answer_delay(), "msg_control", {"option": 0, "command": answer})


    def _set_freq_next(self, which: str, now: float, old: float) -> float:
        """When ``which`` reports next after a Set Freq write changed its interval from ``old`` seconds (R9a:
        within the longer of the old and new interval plus a slack), as ``set_freq_timer`` says; with the fault
        'report_restart_late', one and a half of the longer interval after the write."""
        self.state.regrid.pop(which, None)
        self.state.report_floor = now
        scheduled = self.state.next_report.get(which, now)  # the report already due on the old interval
        new = self._interval(which)
        if "report_restart_late" in self.faults:
            return round(now + 1.5 * max(old, new), 9)
        timer = self.config.set_freq_timer
        if timer == "old_deadline":
            return max(scheduled, now)
        if timer == "restart":
            return round(now + new, 9)
        if timer == "at_once":
            return now
        return max(now, round(scheduled - old + new, 9))  # "last_report": the new interval from the last report
