#!/usr/bin/env python3
"""Clean-room CKESC ESC: an independent implementation of an ESC speaking the CKESC UAVCAN
Protocol 2.1, written from the protocol document (and the project's INTERPRETATIONS.md) only.

One real-time loop: absolute monotonic deadlines, bus.recv(timeout <= 5 ms), signals handled
in the main thread (SIGUSR1 power off, SIGUSR2 power on, SIGTERM/SIGINT save flash and exit).
Only python-can and the standard library.
"""
from __future__ import annotations

import argparse
import copy
import heapq
import json
import os
import signal
import sys
import time

import can

# ---------------------------------------------------------------------------------------------
# Frame ids and priorities (4.3.2)
# ---------------------------------------------------------------------------------------------
HIGHEST, HIGH, MEDIUM, LOW, LOWEST = 0x00, 0x08, 0x10, 0x18, 0x1F

MSG_CAN_TEST = 20000
MSG_CONTROL = 20010
MSG_GET_ESC_ID = 20013
MSG1, MSG2, MSG3 = 20050, 20051, 20052
EXP1, EXP7, EXP8, EXP9, EXP10, EXP11, EXP12 = 20053, 20059, 20060, 20061, 20062, 20063, 20064
RAW14, RAW12, RAW10 = 20100, 20101, 20102

SRV_SET_ID, SRV_SET_BAUD, SRV_SET_LED, SRV_SET_ROT = 210, 211, 212, 213
SRV_FREQ, SRV_THR_SEL, SRV_SELF_TEST = 214, 215, 216
SRV_EXPAND, SRV_GET_REC, SRV_CLEAR_REC = 222, 223, 224
SRV_INFO, SRV_MAINT, SRV_MAJOR = 240, 241, 242

SERVICE_PRIORITY = {
    SRV_SET_ID: MEDIUM, SRV_SET_BAUD: MEDIUM, SRV_SET_LED: LOW, SRV_SET_ROT: LOW,
    SRV_FREQ: MEDIUM, SRV_THR_SEL: MEDIUM, SRV_SELF_TEST: LOWEST, SRV_EXPAND: MEDIUM,
    SRV_GET_REC: MEDIUM, SRV_CLEAR_REC: MEDIUM,
    # 240/241/242 have no priority in the table (F5): this vendor answers them at LOW.
    SRV_INFO: LOW, SRV_MAINT: LOW, SRV_MAJOR: LOW,
}

DEFAULT_NODE = 0x7D
BAUD_RATES = [1000000, 500000, 250000, 200000, 125000, 100000, 50000]   # Set Baud codes (4.4.19)
WINDOW_S = 120.0          # Set ID / Set Baud window after power-up (4.3.2, R11)
COMM_LOSS_S = 0.200       # 4.4.4-3
SERVICE_DELAY_S = 0.0042  # this vendor's answer delay for ordinary services
CAN_TEST_PERIOD_S = 0.010 # CAN Test frame period (the document gives none)
ACCUM_SAVE_S = 60.0       # accumulated running time is saved once a minute

# ESC Information (240): 12S, 80 A (x10 A -> 8), hw 3, protocol 21, firmware 2025-03-17
ESC_INFO = bytes([12, 8, 3, 21, 25, 3, 17])

DEFECTS = {
    "freq_save_clobbers_rotation":
        "a Set Freq write saves the whole config block from the boot-time copy, putting back the "
        "rotation the ESC booted with (4.4.21-4, R13)",
    "resume_reloads_default_intervals":
        "MSG Control resume after a suspension reloads the factory report intervals 10/50/250 into RAM "
        "(4.4.22-6, R9)",
    "led_ram_saved_by_other_writes":
        "any later flash save (rotation, Set Freq, ...) writes the RAM LED, so an LED set with option 0 "
        "survives a power cycle (4.4.20-2, R13)",
    "powerup_counted_twice_after_baud":
        "the first power-up after a Set Baud write re-runs the boot counter and counts two power-ups "
        "(241 option 2, EXP8)",
    "commloss_sticks_after_can_test":
        "once CAN Test mode has been on in this power cycle, a new RawCommand no longer clears the "
        "comm-loss flag (4.4.4-3, R8)",
    "exp_exit_drops_msg3":
        "leaving MSG_EXP mode with 0xAAAAAAAA resumes MSG1 and MSG2 but not MSG3 (4.4.2, R9)",
    "flash_save_closes_window":
        "any flash save (Set Freq write, LED save, rotation, ...) ends the 120 s Set ID / Set Baud "
        "window early (4.3.2, R11)",
    "throttle_select_breaks_10b":
        "after a Throttle Select write the 10-bit RawCommand is no longer decoded: under a 10-bit stream "
        "the comm-loss flag comes up and stays (4.4.17, 4.4.4-3, R5, R8)",
    "rotation_query_saves_suspend":
        "a rotation query (213, 0xFF) while reporting is suspended saves the RAM state block, the "
        "suspension included: the ESC stays silent after the next power-up (4.4.18-4, R13)",
    "answer_slot_from_boot_node":
        "MSG Control / GET_ESC_ID answer slots are computed from the node id the ESC booted with, not "
        "the one Set ID gave it (4.4.2-4, 4.4.3-4, R2)",
}

FACTORY = {
    "node_id": DEFAULT_NODE,
    "channel": 1,
    "baud": 1,
    "led_color": 2,        # default green (4.4.20-3)
    "led_blink": 0,
    "rotation": 0,
    "msg1": 10, "msg2": 50, "msg3": 250,
    "throttle_src": 0,
    "freewheel": 0, "prop_lock": 0, "start_accel": 8, "lost_signal": 8,
    "reporting_suspended": False,   # only ever written by a defect
    "baud_written": False,          # only used by a defect
    "counters": {"power_ups": 0, "starts": 0, "stops": 0, "accum_s": 0},
    "records": {"mcu": [41, 3, 1200], "mos": [58, 2, 950], "cap": [47, 2, 950], "motor": [0, 0, 0]},
}


def tail(tid: int) -> int:
    return 0xC0 | (tid & 0x1F)


def msg_id(prio: int, type_id: int, src: int) -> int:
    return (prio << 24) | (type_id << 8) | (src & 0x7F)


def srv_id(prio: int, service: int, request: bool, dest: int, src: int) -> int:
    return (prio << 24) | (service << 16) | (int(request) << 15) | ((dest & 0x7F) << 8) | 0x80 | (src & 0x7F)


# ---------------------------------------------------------------------------------------------
# RawCommand decoders (4.4.15-17, R3-R5)
# ---------------------------------------------------------------------------------------------
def decode_14b(data: bytes) -> list[int]:
    """MSB-first bit stream, each channel as its low 8 bits then its high 6 bits."""
    bits = int.from_bytes(data[:7], "big")  # 56 bits, first bit is the MSB
    out = []
    for ch in range(4):
        chunk = (bits >> (56 - 14 * (ch + 1))) & 0x3FFF
        low8 = chunk >> 6
        high6 = chunk & 0x3F
        out.append((high6 << 8) | low8)
    return out


def decode_12b(data: bytes) -> tuple[int, list[int]]:
    p = data
    a = p[0] | ((p[1] & 0x0F) << 8)
    b = (p[1] >> 4) | (p[2] << 4)
    c = p[3] | ((p[4] & 0x0F) << 8)
    d = (p[4] >> 4) | (p[5] << 4)
    return p[6], [a, b, c, d]


def decode_10b(data: bytes) -> list[int]:
    v = int.from_bytes(data[:8], "little")
    return [(v >> (10 * i)) & 0x3FF for i in range(6)]


class Esc:
    def __init__(self, args):
        self.args = args
        self.defects = set(args.defect or [])
        self.flash_path = args.flash
        self.flash = self._load_flash(args.node)
        self.bus = None
        self.powered = False
        self.events: list = []
        self.report_gen: dict = {}
        self.seq = 0
        self.tids: dict = {}
        self.stop_requested = False
        self._rate_checked = -1.0
        self._bus_rate = 0
        self.baud_now = self.flash["baud"]
        self.pending_power: list[str] = []

    # ----- flash -----------------------------------------------------------------------------
    def _load_flash(self, node):
        data = copy.deepcopy(FACTORY)
        if node is not None:
            data["node_id"] = node
        if self.flash_path and os.path.exists(self.flash_path):
            try:
                with open(self.flash_path) as f:
                    stored = json.load(f)
                for k, v in stored.items():
                    if k in data:
                        data[k] = v
            except (OSError, ValueError):
                pass
        return data

    def _write_flash_file(self):
        if not self.flash_path:
            return
        tmp = self.flash_path + ".tmp"
        with open(tmp, "w") as f:
            json.dump(self.flash, f, indent=1, sort_keys=True)
        os.replace(tmp, self.flash_path)

    def save(self, reason: str):
        """Write the settings block (RAM -> FLASH), as the document says settings are saved."""
        block = {k: self.ram[k] for k in ("node_id", "channel", "baud", "rotation", "msg1", "msg2", "msg3",
                                          "throttle_src", "freewheel", "prop_lock", "start_accel",
                                          "lost_signal")}
        if "led_ram_saved_by_other_writes" in self.defects:
            block["led_color"], block["led_blink"] = self.led_ram
        else:
            block["led_color"], block["led_blink"] = self.ram["led_color"], self.ram["led_blink"]
        if "freq_save_clobbers_rotation" in self.defects and reason == "freq":
            block["rotation"] = self.boot_cfg["rotation"]
            self.ram["rotation"] = self.boot_cfg["rotation"]
        if "rotation_query_saves_suspend" in self.defects:
            block["reporting_suspended"] = self.suspended
        self.flash.update(block)
        self.flash["counters"]["accum_s"] = self.accum_s()
        self.accum_saved_at = time.monotonic()
        self._write_flash_file()
        if "flash_save_closes_window" in self.defects:
            self.window_end = min(self.window_end, time.monotonic())

    def save_counters(self):
        self.flash["counters"]["accum_s"] = self.accum_s()
        self.accum_saved_at = time.monotonic()
        self._write_flash_file()

    def accum_s(self) -> int:
        if not self.powered:
            return self.flash["counters"]["accum_s"]
        return self.accum_base + int(time.monotonic() - self.power_on_t)

    # ----- scheduling --------------------------------------------------------------------------
    def at(self, t: float, fn, *a):
        self.seq += 1
        heapq.heappush(self.events, (t, self.seq, self.epoch, fn, a))

    def on_our_rate(self) -> bool:
        """With --bus-bitrate-file, the ESC hears and is heard only when the bus runs at its own rate."""
        path = self.args.bus_bitrate_file
        if not path:
            return True
        try:
            st = os.stat(path).st_mtime_ns
        except OSError:
            st = None
        if st != self._rate_checked:
            self._rate_checked = st
            try:
                with open(path) as f:
                    self._bus_rate = int(f.read().strip() or 0)
            except (OSError, ValueError):
                self._bus_rate = 0
        return not self._bus_rate or self._bus_rate == BAUD_RATES[self.baud_now]

    def send(self, arb_id: int, data: bytes):
        if not self.powered or self.bus is None or not self.on_our_rate():
            return
        try:
            self.bus.send(can.Message(arbitration_id=arb_id, is_extended_id=True, data=data))
        except can.CanError as e:
            print(f"send failed: {e}", file=sys.stderr, flush=True)

    def next_tid(self, key) -> int:
        t = (self.tids.get(key, 0) + 1) & 0x1F   # pre-incremented: the first transfer carries 1
        self.tids[key] = t
        return t

    def broadcast(self, prio: int, type_id: int, payload: bytes):
        tid = self.next_tid((type_id, None))
        self.send(msg_id(prio, type_id, self.ram["node_id"]), bytes(payload) + bytes([tail(tid)]))

    def respond(self, service: int, dest: int, tid: int, payload: bytes, src: int | None = None):
        src = self.ram["node_id"] if src is None else src
        self.send(srv_id(SERVICE_PRIORITY[service], service, False, dest, src), bytes(payload) + bytes([tail(tid)]))

    # ----- power -------------------------------------------------------------------------------
    def power_on(self):
        now = time.monotonic()
        self.powered = True
        self.epoch = getattr(self, "epoch", 0) + 1
        self.events = []
        self.tids = {}
        self.power_on_t = now
        self.boot_until = now + self.args.boot_time
        self.window_end = now + WINDOW_S
        # RAM state from FLASH
        self.ram = copy.deepcopy({k: v for k, v in self.flash.items() if k not in ("counters", "records")})
        self.boot_cfg = copy.deepcopy(self.ram)
        self.boot_node = self.ram["node_id"]
        self.baud_now = self.ram["baud"]   # Set Baud takes effect at power-up (4.4.19-1)
        self.led_ram = (self.ram["led_color"], self.ram["led_blink"])
        self.suspended = bool(self.flash.get("reporting_suspended")) and "rotation_query_saves_suspend" in self.defects
        self.exp_mode = False
        self.exp_exit_dropped_msg3 = False
        self.can_test = False
        self.can_test_used = False
        self.can_test_count = 0
        self.test_mode = False
        self.throttle_select_written = False
        self.throttle = 0
        self.rpm = 0.0
        self.running = False
        self.comm_fault = False
        self.last_cmd_t = self.boot_until
        self.run_start_t = None
        self.accum_base = self.flash["counters"]["accum_s"]
        self.accum_saved_at = now
        c = self.flash["counters"]
        c["power_ups"] = (c["power_ups"] + 1) & 0xFFFF
        if "powerup_counted_twice_after_baud" in self.defects and self.flash.get("baud_written"):
            c["power_ups"] = (c["power_ups"] + 1) & 0xFFFF
        self.flash["baud_written"] = False
        self._write_flash_file()
        # reports start one interval after boot (a node still at 0x7D reports nothing: 4.4.18-4)
        self.reporting_on = self.ram["node_id"] != DEFAULT_NODE
        self.restart_reports(self.boot_until)
        self.at(self.boot_until, self.tick_motor)

    def power_off(self):
        self.powered = False
        self.events = []
        self.epoch = getattr(self, "epoch", 0) + 1

    # ----- reports -----------------------------------------------------------------------------
    def restart_reports(self, t0: float, which=("msg1", "msg2", "msg3")):
        """(Re)start report timers: the first report of each type one interval after t0 (R9a)."""
        for k in which:
            self.report_gen[k] = self.report_gen.get(k, 0) + 1
            self.events_push_report(t0 + self.ram[k] * 0.002, k, self.report_gen[k])

    def reports_allowed(self) -> bool:
        return self.reporting_on and not self.suspended and not self.can_test

    def report(self, kind: str, gen: int, due: float | None = None):
        if gen != self.report_gen.get(kind):
            return
        now = time.monotonic()
        due = now if due is None else due
        interval = self.ram[kind] * 0.002
        nxt = due + interval
        if nxt < now - interval:        # fell far behind (machine stalled): re-anchor
            nxt = now + interval
        self.events_push_report(nxt, kind, gen)
        if not self.reports_allowed():
            return
        if self.exp_mode:
            self.send_exp(kind)
            return
        if kind == "msg3" and self.exp_exit_dropped_msg3:
            return
        if kind == "msg1":
            self.broadcast(LOWEST, MSG1, self.msg1_payload())
        elif kind == "msg2":
            self.broadcast(LOWEST, MSG2, self.msg2_payload())
        else:
            self.broadcast(LOWEST, MSG3, bytes([self.mos_t(), 29, 0, 37, 0, 0, 0]))

    def events_push_report(self, t, kind, gen):
        self.seq += 1
        heapq.heappush(self.events, (t, self.seq, self.epoch, self.report_at, (kind, gen, t)))

    def report_at(self, kind, gen, due):
        self.report(kind, gen, due)

    def mos_t(self) -> int:
        return 31 + int(self.throttle / 200)

    def status_word(self) -> int:
        now = time.monotonic()
        self.update_comm(now)
        s = 0
        if self.ram["rotation"]:
            s |= 1 << 15
        if self.ram["throttle_src"] and self.args.source_bit == "configured":
            s |= 1 << 14   # this vendor: bit 14 shows the configured source (PWM+CAN), see README
        if self.comm_fault:
            s |= 1 << 13
        if self.running:
            s |= 1 << 8
        return s

    def msg1_payload(self) -> bytes:
        return (int(self.rpm) & 0xFFFF).to_bytes(2, "little") + (self.throttle & 0xFFFF).to_bytes(2, "little") + \
            self.status_word().to_bytes(2, "little")

    def voltage(self) -> int:
        return 2516 - self.throttle // 40

    def current(self) -> int:
        return self.throttle * 3 // 2

    def msg2_payload(self) -> bytes:
        return self.voltage().to_bytes(2, "little") + self.current().to_bytes(2, "little") + bytes([self.mos_t()])

    def send_exp(self, kind: str):
        # MSG_EXP mode (R9, OBSERVE which and how often): EXP1 on MSG1's interval, EXP11 on MSG2's,
        # EXP7..EXP10 on MSG3's.
        if kind == "msg1":
            self.broadcast(LOWEST, EXP1, int(self.rpm).to_bytes(2, "little") + self.voltage().to_bytes(2, "little")
                           + self.current().to_bytes(2, "little"))
        elif kind == "msg2":
            self.broadcast(LOWEST, EXP11, bytes([self.mos_t(), 37, 29, 0, 0, 0]))
        else:
            for fn in (self.exp7, self.exp8, self.exp9, self.exp10):
                fn()

    def exp7_payload(self) -> bytes:
        r = self.ram
        direction = 2 if r["rotation"] else 1
        color = r["led_color"] if not hasattr(self, "led_ram") else self.led_ram[0]
        led = 1 if color & 4 else 2 if color & 2 else 3 if color & 1 else 0
        iface = 2 if r["throttle_src"] else 3
        return bytes([direction | (led << 4), iface, r["freewheel"] & 0x0F, 0,
                      (r["prop_lock"] & 0x0F) | ((r["start_accel"] & 0x0F) << 4), r["lost_signal"] & 0x0F])

    def exp7(self):
        self.broadcast(LOWEST, EXP7, self.exp7_payload())

    def exp8(self):
        c = self.flash["counters"]
        self.broadcast(LOWEST, EXP8, c["power_ups"].to_bytes(2, "little") + c["starts"].to_bytes(2, "little")
                       + c["stops"].to_bytes(2, "little"))

    def exp9(self):
        self.broadcast(LOWEST, EXP9, (self.accum_s() & 0xFFFFFFFF).to_bytes(4, "little") + bytes([0, 0]))

    def exp10(self):
        self.broadcast(LOWEST, EXP10, int(time.monotonic() - self.power_on_t).to_bytes(4, "little") + bytes([0, 0]))

    def can_test_tick(self):
        if not self.can_test:
            return
        self.broadcast(LOWEST, MSG_CAN_TEST, bytes([0x00]) + self.can_test_count.to_bytes(4, "little"))
        self.can_test_count = (self.can_test_count + 1) & 0xFFFFFFFF
        self.can_test_due += CAN_TEST_PERIOD_S
        if self.can_test_due < time.monotonic() - CAN_TEST_PERIOD_S:
            self.can_test_due = time.monotonic() + CAN_TEST_PERIOD_S
        self.at(self.can_test_due, self.can_test_tick_gen, self.can_test_gen)

    def can_test_tick_gen(self, gen):
        if gen == self.can_test_gen:
            self.can_test_tick()

    # ----- motor / comm ------------------------------------------------------------------------
    def update_comm(self, now: float):
        if self.ram["throttle_src"] == 0 and now - self.last_cmd_t > COMM_LOSS_S:
            if not self.comm_fault:
                self.comm_fault = True
                self.throttle = 0   # lost signal: throttle reduced to zero

    def tick_motor(self):
        now = time.monotonic()
        self.update_comm(now)
        target = self.throttle * 6.0
        self.rpm += (target - self.rpm) * 0.25
        if self.rpm < 1.0 and self.throttle == 0:
            self.rpm = 0.0
        running = self.throttle > 0
        if running != self.running:
            c = self.flash["counters"]
            if running:
                c["starts"] = (c["starts"] + 1) & 0xFFFF
            else:
                c["stops"] = (c["stops"] + 1) & 0xFFFF
            self.running = running
            self.save_counters()
        if now - self.accum_saved_at >= ACCUM_SAVE_S:
            self.save_counters()
        self.at(now + 0.010, self.tick_motor)

    def motor_stopped(self) -> bool:
        return self.throttle == 0 and self.rpm < 1.0

    def raw_command(self, values: list[int], first_channel: int, scale: int, limit: int):
        ch = self.ram["channel"]
        idx = ch - first_channel
        if not 0 <= idx < len(values):
            return   # this frame does not carry our channel
        v = values[idx]
        if v > limit:
            return   # out of range: not "correct" data, ignored (R6 OBSERVE)
        self.last_cmd_t = time.monotonic()
        if self.comm_fault and not ("commloss_sticks_after_can_test" in self.defects and self.can_test_used):
            self.comm_fault = False
        if not self.comm_fault:
            self.throttle = v * scale

    # ----- receive -----------------------------------------------------------------------------
    def on_frame(self, m: can.Message, rx_mono: float):
        if not self.powered or rx_mono < self.boot_until or not m.is_extended_id or m.is_remote_frame:
            return
        if not self.on_our_rate():
            return
        if m.is_error_frame:
            return
        cid = m.arbitration_id
        data = bytes(m.data)
        if not data:
            return
        src = cid & 0x7F
        if cid & 0x80:
            service = (cid >> 16) & 0xFF
            request = (cid >> 15) & 1
            dest = (cid >> 8) & 0x7F
            if not request:
                return
            t = data[-1]
            if (t & 0xE0) != 0xC0:
                return   # not a single-frame transfer
            if service != SRV_SET_ID and dest != self.ram["node_id"]:
                return
            self.on_service(service, src, t & 0x1F, data[:-1], m, rx_mono)
            return
        type_id = (cid >> 8) & 0xFFFF
        if src == self.ram["node_id"] and src != 0:
            return       # our own echo (node ids are unique on a bus)
        if type_id == RAW10:
            if len(data) >= 8:
                if "throttle_select_breaks_10b" in self.defects and self.throttle_select_written:
                    return
                self.raw_command(decode_10b(data), 1, 2, 1000)
            return
        t = data[-1]
        if (t & 0xE0) != 0xC0:
            return
        payload = data[:-1]
        if type_id == RAW14 and len(payload) >= 7:
            self.raw_command(decode_14b(payload), 1, 1, 2000)
        elif type_id == RAW12 and len(payload) >= 7:
            group, vals = decode_12b(payload)
            if 1 <= group <= 5:
                self.raw_command(vals, 4 * group - 3, 1, 2000)
        elif type_id == MSG_GET_ESC_ID and len(payload) == 1 and payload[0] == 0:
            self.at_slot(m, rx_mono, self.answer_get_id)
        elif type_id == MSG_CONTROL and len(payload) >= 5 and payload[0] == 0:
            cmd = int.from_bytes(payload[1:5], "little")
            if cmd in (0x55555555, 0xAAAAAAAA, 0xEEEEEEEE):
                self.msg_control(cmd)
                self.at_slot(m, rx_mono, self.answer_msg_control)
        elif type_id == MSG_CAN_TEST and len(payload) >= 1:
            if payload[0] == 0xAA and not self.can_test:
                self.can_test = True
                self.can_test_used = True
                self.can_test_gen = getattr(self, "can_test_gen", 0) + 1
                self.can_test_due = time.monotonic() + CAN_TEST_PERIOD_S
                self.at(self.can_test_due, self.can_test_tick_gen, self.can_test_gen)
            elif payload[0] == 0x55 and self.can_test:
                self.can_test = False
                self.can_test_gen += 1
                self.restart_reports(time.monotonic())

    def at_slot(self, m: can.Message, rx_mono: float, fn):
        node = self.boot_node if "answer_slot_from_boot_node" in self.defects else self.ram["node_id"]
        offset = (node % 32) * 0.002 + 0.0008
        # time the slot from the request's bus timestamp where it is on our wall clock
        lag = time.time() - m.timestamp if m.timestamp else 0.0
        if not 0.0 <= lag < 0.030:
            lag = 0.0
        self.at(rx_mono - lag + offset, fn)

    def answer_get_id(self):
        self.broadcast(MEDIUM, MSG_GET_ESC_ID, bytes([self.ram["node_id"], self.ram["channel"]]))

    def answer_msg_control(self):
        self.broadcast(MEDIUM, MSG_CONTROL, bytes([0, 0, 0, 0, 0]))

    def msg_control(self, cmd: int):
        now = time.monotonic()
        if cmd == 0x55555555:
            self.suspended = True
            return
        was_suspended, was_exp, was_on = self.suspended, self.exp_mode, self.reporting_on
        self.suspended = False
        self.reporting_on = True
        if cmd == 0xAAAAAAAA:
            self.exp_mode = False
            if was_exp and "exp_exit_drops_msg3" in self.defects:
                self.exp_exit_dropped_msg3 = True
            if was_suspended and "resume_reloads_default_intervals" in self.defects:
                for k in ("msg1", "msg2", "msg3"):
                    self.ram[k] = FACTORY[k]
        else:
            self.exp_mode = True
        if was_suspended or was_exp != self.exp_mode or not was_on:
            self.restart_reports(now)

    # ----- services ----------------------------------------------------------------------------
    def on_service(self, service, src, tid, p: bytes, m, rx_mono):
        reply = []   # (payload) answered after SERVICE_DELAY_S

        def answer(payload, src_node=None):
            reply.append((bytes(payload), src_node))

        changes_ok = not self.suspended    # R12: no parameter change while reporting is suspended
        now = time.monotonic()
        r = self.ram
        if service == SRV_SET_ID:
            if len(p) < 2 or now > self.window_end:
                return
            node, ch = p[0], p[1]
            if not (1 <= node <= 0x7D and 1 <= ch <= 20):
                return   # illegal: ignored, not answered
            if changes_ok:
                r["node_id"], r["channel"] = node, ch
                self.save("set_id")
                if node == DEFAULT_NODE:
                    self.reporting_on = False   # at 0x7D nothing is reported on its own (4.4.18-4)
            answer([r["node_id"], r["channel"]])
        elif service == SRV_SET_BAUD:
            if len(p) < 1 or now > self.window_end or p[0] > 6:
                return
            if changes_ok:
                r["baud"] = p[0]
                self.save("baud")
                self.flash["baud_written"] = True
                self._write_flash_file()
            answer([r["baud"]])
        elif service == SRV_SET_LED:
            if len(p) < 3:
                return
            if p[0] > 1:
                if self.args.led_other_option == "ignore":
                    return   # this vendor: an option other than 0/1 is not answered
                answer([p[0], self.led_ram[0], self.led_ram[1]])   # answered, nothing changed
                p = b""
            if p and changes_ok:
                color = p[1] & 0x07
                blink = p[2] if p[2] in (0, 1, 2, 5) else 0
                self.led_ram = (color, blink)
                if p[0] == 1:
                    r["led_color"], r["led_blink"] = color, blink
                    self.save("led")
            if p:
                answer([p[0], self.led_ram[0], self.led_ram[1]])
        elif service == SRV_SET_ROT:
            if len(p) < 1:
                return
            v = p[0]
            if v in (0, 1) and changes_ok and self.motor_stopped():
                r["rotation"] = v
                self.save("rotation")
            elif v == 0xFF and self.suspended and "rotation_query_saves_suspend" in self.defects:
                self.save("query")
            answer([r["rotation"]])
        elif service == SRV_FREQ:
            if len(p) < 4 or (p[0] > 1 and self.args.freq_other_option == "ignore"):
                return   # this vendor: an option other than 0 (read) / 1 (write) is not answered
            if p[0] == 1 and changes_ok and all(10 <= x <= 250 for x in p[1:4]):
                # the report already scheduled on the old interval goes out first (R9a); the one
                # after it comes on the new interval
                r["msg1"], r["msg2"], r["msg3"] = p[1], p[2], p[3]
                self.save("freq")
            answer([p[0], r["msg1"], r["msg2"], r["msg3"]])
        elif service == SRV_THR_SEL:
            if len(p) < 1:
                return
            if p[0] in (0, 1) and changes_ok and self.throttle == 0:
                r["throttle_src"] = p[0]
                self.throttle_select_written = True
                self.save("throttle")
            answer([r["throttle_src"]])
        elif service == SRV_SELF_TEST:
            answer([0x00])
        elif service == SRV_EXPAND:
            if len(p) >= 3 and changes_ok and self.motor_stopped():
                self.expand(int.from_bytes(p[0:2], "little"), p[2])
            return       # no answer frame (4.4.25)
        elif service == SRV_GET_REC:
            self.send_records()
            return
        elif service == SRV_CLEAR_REC:
            for k in self.flash["records"]:
                self.flash["records"][k] = [0, 0, 0]
            self._write_flash_file()
            answer([])
        elif service == SRV_INFO:
            answer(ESC_INFO)
        elif service == SRV_MAINT:
            if len(p) < 1 or p[0] > 2:
                return
            c = self.flash["counters"]
            if p[0] == 0:
                rec = self.flash["records"]
                answer((self.accum_s() & 0xFFFFFFFF).to_bytes(4, "little") + bytes([rec["mos"][0], rec["cap"][0], 0]))
            elif p[0] == 1:
                answer(int(now - self.power_on_t).to_bytes(4, "little") + c["starts"].to_bytes(2, "little") + bytes([1]))
            else:
                answer(c["power_ups"].to_bytes(2, "little") + c["stops"].to_bytes(2, "little") + bytes([0, 0, 2]))
        elif service == SRV_MAJOR:
            b0 = (r["rotation"] << 7) | (r["throttle_src"] << 6) | (r["channel"] & 0x3F)
            b1 = ((self.led_ram[1] & 0x1F) << 3) | (self.led_ram[0] & 0x07)
            answer([b0, b1, r["msg1"], r["msg2"], r["msg3"], 0, 0])
        else:
            return
        for payload, src_node in reply:
            self.at(rx_mono + SERVICE_DELAY_S, self.respond, service, src, tid, payload, src_node)

    def expand(self, cmd: int, part: int):
        r = self.ram
        if cmd == 0xFFF0 and part in (1, 2):
            r["rotation"] = part - 1
        elif cmd == 0xFFF1 and part <= 3:
            color = {0: 0, 1: 4, 2: 2, 3: 1}[part]
            r["led_color"], r["led_blink"] = color, 0
            self.led_ram = (color, 0)
        elif cmd == 0xFFF2 and part in (2, 3, 5, 6):
            r["throttle_src"] = 1 if part in (2, 5) else 0
        elif cmd == 0xFFF4 and part <= 1:
            r["freewheel"] = part
        elif cmd == 0xFFF8 and part <= 3:
            r["prop_lock"] = part
        elif cmd == 0xFFF9 and part <= 15:
            r["start_accel"] = part
        elif cmd == 0xFFFA and part <= 15:
            r["lost_signal"] = part
        elif cmd == 0xFFFB and part == 1:
            self.send_records()
            return
        elif cmd == 0xFFFC and part <= 6:
            r["baud"] = part
        elif cmd == 0xFFFE and part in (0x10, 0x11):
            self.test_mode = part == 0x11
            return
        else:
            return       # reserved or unknown: nothing
        self.save("expand")

    def send_records(self):
        rec = self.flash["records"]
        now = time.monotonic()
        for i, k in enumerate(("mcu", "mos", "cap", "motor")):
            t_max, times, t = rec[k]
            payload = bytes([t_max & 0xFF]) + (times & 0xFFFF).to_bytes(2, "little") + (t & 0xFFFFFFFF).to_bytes(4, "little")
            arb = msg_id(LOWEST, EXP12, self.ram["node_id"])
            self.at(now + 0.002 * (i + 1), self.send, arb, payload + bytes([0xC1 + i]))

    # ----- main loop ---------------------------------------------------------------------------
    def run(self):
        kwargs = {}
        for kv in self.args.bus_arg or []:
            k, _, v = kv.partition("=")
            kwargs[k] = {"True": True, "False": False}.get(v, int(v) if v.isdigit() else v)
        if self.args.interface == "socketcand":
            kwargs.setdefault("tcp_tune", True)
        self.bus = can.Bus(interface=self.args.interface, channel=self.args.channel, **kwargs)
        self.epoch = 0
        signal.signal(signal.SIGUSR1, lambda *_: self.pending_power.append("off"))
        signal.signal(signal.SIGUSR2, lambda *_: self.pending_power.append("on"))
        signal.signal(signal.SIGTERM, self._stop)
        signal.signal(signal.SIGINT, self._stop)
        if not self.args.unpowered:
            self.power_on()
        print(f"ready pid={os.getpid()}", flush=True)
        try:
            while not self.stop_requested:
                while self.pending_power:
                    what = self.pending_power.pop(0)
                    if what == "off" and self.powered:
                        self.power_off()
                    elif what == "on" and not self.powered:
                        self.power_on()
                now = time.monotonic()
                while self.events and self.events[0][0] <= now:
                    _, _, epoch, fn, a = heapq.heappop(self.events)
                    if epoch == self.epoch and self.powered:
                        fn(*a)
                    now = time.monotonic()
                timeout = 0.005
                if self.events:
                    timeout = max(0.0, min(timeout, self.events[0][0] - now))
                try:
                    m = self.bus.recv(timeout)
                except can.CanError as e:
                    print(f"recv failed: {e}", file=sys.stderr, flush=True)
                    time.sleep(0.005)
                    continue
                while m is not None:
                    self.on_frame(m, time.monotonic())
                    m = self.bus.recv(0)
        finally:
            if self.powered:
                self.save_counters()
            self._write_flash_file()
            self.bus.shutdown()

    def _stop(self, *_):
        self.stop_requested = True


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--interface", default="socketcand")
    ap.add_argument("--channel", default="can0")
    ap.add_argument("--bus-arg", action="append", metavar="KEY=VALUE")
    ap.add_argument("--node", type=int, default=None, help="factory node id when the flash file has none")
    ap.add_argument("--flash", default=None, help="flash file (JSON)")
    ap.add_argument("--defect", action="append", metavar="NAME")
    ap.add_argument("--list-defects", action="store_true")
    ap.add_argument("--unpowered", action="store_true")
    ap.add_argument("--bus-bitrate-file", default=None,
                    help="bench stand-in for the physical bit rate: a file holding the bus's bit rate; the ESC "
                         "is deaf and mute while it differs from the rate of the ESC's Set Baud code")
    ap.add_argument("--source-bit", choices=("configured", "in-use"), default="configured",
                    help="MSG1 status bit 14: the configured throttle source (default) or the source in use "
                         "(CAN: this ESC has no PWM input)")
    ap.add_argument("--freq-other-option", choices=("ignore", "read"), default="ignore",
                    help="Set/Get Freq with an option other than 0/1: not answered (default) or taken as a read")
    ap.add_argument("--led-other-option", choices=("ignore", "answer"), default="ignore",
                    help="Set LED with an option other than 0/1: not answered (default) or answered, nothing changed")
    ap.add_argument("--boot-time", type=float, default=0.3)
    args = ap.parse_args(argv)
    if args.list_defects:
        for k, v in DEFECTS.items():
            print(f"{k}: {v}")
        return 0
    for d in args.defect or []:
        if d not in DEFECTS:
            print(f"unknown defect {d!r} (--list-defects)", file=sys.stderr)
            return 2
    if args.node is not None and not 1 <= args.node <= 0x7D:
        print("--node must be 1..125", file=sys.stderr)
        return 2
    Esc(args).run()
    return 0


if __name__ == "__main__":
    sys.exit(main())
