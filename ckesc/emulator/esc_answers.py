"""The requests an emulated ESC answers without changing a setting: GET_ESC_ID (R1), Self Test, the temperature
records (Get Rec / Clear Rec, R15), ESC Information (240), Maintenance Information (241), Get Major Configuration
(242), and the DroneCAN node info a fault answers."""

from __future__ import annotations

from typing import Any

from ..protocol.frame import Frame, WireFrame
from ..protocol.ids import Priority, message_id, service_id
from ..protocol.transfer import tail_byte, tail_transfer_id
from .config import RECORD_SENSORS


class Answers:
    """Part of :class:`~ckesc.emulator.model.EscModel`: answers to requests that read."""

    def _on_get_esc_id(self, f: Frame, now: float) -> None:
        if f.layout is None or f.layout.name != "query" or f.fields["option"] != 0:
            self.counters["rx_ignored"] += 1  # a reply from another ESC, or an unknown option
            return
        due = now + self._answer_delay()
        node = self.node_id + 1 if "get_esc_id_wrong_node" in self.faults else self.node_id
        channel = self.nvm["throttle_channel"]
        if "get_esc_id_with_option" in self.faults:
            self._emit_raw(due, 20013, bytes([0, node, channel]), Priority.MEDIUM)
            return
        self._emit(due, "get_esc_id", {"node_id": node, "throttle_channel": channel}, layout="reply")


    def _on_self_test(self, f: Frame, now: float) -> None:
        if not self._addressed(f) or "self_test_unanswered" in self.faults:
            return
        failed = self.state.self_test_fault != 0 and "self_test_always_passes" not in self.faults
        if "self_test_inverted" in self.faults:
            failed = not failed
        self._respond(f, now, {"status": int(failed)})


    def _send_records(self, now: float) -> None:
        if "get_rec_absent" in self.faults:
            return
        due = now + self.config.service_delay
        for index, sensor in enumerate(RECORD_SENSORS, start=1):
            rec = self.nvm["records"][sensor]
            tag = 0 if "get_rec_untagged" in self.faults else index
            self._emit(due, "msg_exp12", {"t_max": rec["t_max"], "times": rec["times"] & 0xFFFF,
                                          "time": rec["time"] & 0xFFFFFFFF}, transfer_id=tag)


    def _on_get_rec(self, f: Frame, now: float) -> None:
        if self._addressed(f):
            if self.config.rec_answer == "echo" and "get_rec_absent" not in self.faults:
                self._echo_request(f, now)
            self._send_records(now)

    def _on_clear_rec(self, f: Frame, now: float) -> None:
        if self._addressed(f) and not {"clear_rec_ignored", "get_rec_absent"} & self.faults:
            if self.config.rec_answer == "echo":
                self._echo_request(f, now)
            self._set_nvm(records={s: {"t_max": 0, "times": 0, "time": 0} for s in RECORD_SENSORS})

    def _on_esc_information(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        c = self.config
        year, month, day = c.firmware_date
        if "esc_information_bcd_date" in self.faults:  # October -> 0x10 = 16
            year, month, day = (int(str(v), 16) for v in (year, month, day))
        self._respond(f, now, {"max_cells": c.max_cells, "max_current": c.max_current_10a,
                               "hardware_version": c.hardware_version, "protocol_version": c.protocol_version,
                               "firmware_year": year, "firmware_month": month, "firmware_day": day})

    def _on_maintenance(self, f: Frame, now: float) -> None:
        if not self._addressed(f):
            return
        option, n = f.fields["option"], self.nvm
        if option == 0:
            fields = {"total_run_time": self._whole(n["total_run_time"]), "mos_t_max": n["records"]["mos"]["t_max"],
                      "cap_t_max": n["records"]["cap"]["t_max"], "info_7": 0}
        elif option == 1:
            fields = {"run_time": self._whole(self.this_run_time()), "runs": n["starts"], "info_7": 1}
        elif option == 2:
            ups, stops = n["power_ups"], n["stops"]
            if "maintenance_counts_wrong" in self.faults:
                ups, stops = stops, ups
            fields = {"power_ups": ups, "stops": stops, "fault_code": self.state.self_test_fault, "option": 2}
        else:
            self.counters["rx_ignored"] += 1
            return
        self._respond(f, now, fields, layout=f"response_option_{option}")
        if "maintenance_info_7_missing" in self.faults:  # drop Info_7 from the answer just queued
            for i, (due, seq, wire) in enumerate(self.state.outbox):
                if seq == self.state.seq:
                    self.state.outbox[i] = (due, seq, wire._replace(data=wire.data[:6] + wire.data[7:]))

    def _dronecan_node_info(self, msg: Any, now: float) -> bool:
        """Fault 'dronecan_node_info': answer DroneCAN GetNodeInfo (service 1), announcing a
        NodeStatus (message 341) first: ids outside the CKESC vendor ranges (4.3.1)."""
        can_id, data = msg.arbitration_id, bytes(msg.data)
        if not (can_id & 0x8080 == 0x8080 and (can_id >> 16) & 0xFF == 1 and (can_id >> 8) & 0x7F == self.node_id):
            return False
        due = now + self.config.service_delay
        status = bytes(7) + bytes((tail_byte(self.state.tids.next("dronecan341")),))
        self._push(due, WireFrame(message_id(Priority.LOW, 341, self.node_id), status, due))
        answer = bytes(7) + bytes((tail_byte(tail_transfer_id(data[-1]) if data else 0),))
        self._push(due, WireFrame(service_id(Priority.LOW, 1, False, can_id & 0x7F, self.node_id), answer, due))
        return True

    def _on_major_config(self, f: Frame, now: float) -> None:
        if not self._addressed(f) or (f.fields.get("option") and self.config.major_config_option == "ignore"):
            return
        n = self.nvm
        direction, source = n["rotation"], n["throttle_source"]
        if "major_config_bits_swapped" in self.faults:
            direction, source = source, direction
        # one-bit fields: a value stored by throttle_select_accepts_illegal (2, 255) must not crash the model
        self._respond(f, now, {"direction": direction & 1, "throttle_source": source & 1,
                               "throttle_channel": n["throttle_channel"] & 0x3F, "led_blink": self.state.led_blink & 0x1F,
                               "led_color": self.state.led_color & 0x07, "msg1_interval": n["msg1_interval"],
                               "msg2_interval": n["msg2_interval"], "msg3_interval": n["msg3_interval"]})
