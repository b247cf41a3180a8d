"""The real-time emulator's control commands (``status``, ``power``, ``fault``, ``faults``, ``bitrate``,
``bus_fault``, ``bus_settle``, ``stats``, ``save``, ``stop``; the channel and its requests: :mod:`.control`): the handlers a
:class:`.realtime.RealtimeEmulator` runs in its loop thread, kept here as a mixin so that the emulator's
module holds its scheduling loop and IO."""

from __future__ import annotations

import time
from typing import Any

from . import faults as _faults
from .control import Reply
from .hub_can import KINDS
from .realtime_timing import summary
from .socketcand import fmt_error


class ControlCommands:
    """Mixin of :class:`.realtime.RealtimeEmulator`: its ``_cmd_*`` handlers (it provides the bench, the
    ESCs, the statistics and the timers they use)."""

    # attributes the emulator provides
    bench: Any
    _escs: list
    _stopping: bool
    can: Any  # the hub's bus faults (:class:`.hub_can.HubCan`)
    _bus_waiters: list
    _socketcand: Any  # the socketcand hub (:class:`.socketcand.SocketcandServer`) or None

    def _cmd_status(self, req: dict, reply: Reply) -> dict:
        now = time.monotonic()
        escs = []
        for esc in self._escs:
            escs.append({
                "slot": esc.config.slot,
                "node_id": esc.node_id,
                "powered": esc.powered,
                "ready": esc.powered and now >= esc.state.ready_at,
                "bitrate": esc.state.bitrate,
                "on_bus": esc.state.bitrate == self.bitrate,
                "reporting": esc.state.reporting,
                "can_test": esc.state.can_test,
                "comm_fault": esc.state.comm_fault,
                "throttle": esc.state.throttle,
                "faults": sorted(esc.faults),
                "counters": dict(esc.counters),
                "power_ups": esc.nvm.get("power_ups"),
                "can": self.can.state(esc),
            })
        return {
            "powered": self.bench.powered,
            "power_on_in": None if self._power_on_at is None else round(self._power_on_at - now, 6),
            "bitrate": self.bitrate,
            "uptime": round(now - self._t_start, 6),
            "monotonic": now,
            "clock_offset": self.offset,
            "stamp": self.stamp,
            "scheduling": self.scheduling,
            "flash": None if self.bench.flash is None else str(self.bench.flash.path),
            "socketcand": _addr(self.socketcand_address),
            "clients": 0 if self._socketcand is None else len(self._socketcand.conns),
            "counters": dict(self.counters),
            "host_alone": self.host_alone.mode,
            "host_waiting": len(self.host_alone.held),  # held now (counters: host_held, host_lost so far)
            "bus_fault": self.can.describe(now),
            "bus_counters": dict(self.can.counters),
            "lateness": summary(self.lateness),
            "wakeup": summary(self.wakeup),
            "escs": escs,
        }

    def _cmd_power(self, req: dict, reply: Reply) -> dict | None:
        action = req.get("action")
        now = time.monotonic()
        if action == "off":
            self._emit_due(now)
            self._cancel_power_on("power switched off")
            err = self._do_power_off(now)
            return {"powered": False, **({"flash_error": err} if err else {})}
        if action == "on":
            self._cancel_power_on("power switched on")
            self._do_power_on(now)
            return {"powered": True}
        if action == "cycle":
            off_time = req.get("off_time", 1.0)
            if isinstance(off_time, bool) or not isinstance(off_time, (int, float)) or not 0 <= off_time <= 3600:
                raise ValueError(f"off_time must be a number of seconds 0..3600, not {off_time!r}")
            self._emit_due(now)
            self._cancel_power_on("power cycled again")
            err = self._do_power_off(now)
            self._power_on_at = now + off_time
            self._power_waiters.append(lambda answer: reply({**answer, **({"flash_error": err} if err else {})}))
            return None  # answered at power-on
        raise ValueError(f"power action must be off, on or cycle, not {action!r}")

    def _do_power_off(self, now: float) -> str | None:
        self._deadlines_stale = True
        for esc in self._escs:  # a controller off the bus: bus-off and what it held gone with its power
            self.can.forget(esc)
        try:
            self.bench.power_off(now)  # writes the flash file
        except OSError as exc:
            self._log(f"could not write the flash file: {exc}")
            return str(exc)
        return None

    def _do_power_on(self, at: float) -> None:
        self._power_on_at = None
        self.bench.power_on(at)
        self._deadlines_stale = True
        waiters, self._power_waiters = self._power_waiters, []
        for w in waiters:
            w({"ok": True, "powered": True})

    def _cancel_power_on(self, why: str) -> None:
        self._power_on_at = None
        waiters, self._power_waiters = self._power_waiters, []
        for w in waiters:
            w({"ok": False, "error": f"power cycle interrupted: {why}"})

    def _cmd_fault(self, req: dict, reply: Reply) -> dict:
        name, node = req.get("name"), req.get("node")
        on = req.get("on", True)
        if not isinstance(name, str):
            raise ValueError(f"fault name must be a string, not {name!r}; known: {', '.join(sorted(_faults.FAULTS))}")
        if not isinstance(on, bool):
            raise ValueError(f"'on' must be true or false, not {on!r}")
        if node is not None:
            if isinstance(node, bool) or not isinstance(node, int):
                raise ValueError(f"node must be a node id, not {node!r}")
            self.bench.esc(node)  # KeyError naming the node ids present
        self.bench.set_fault(name, on, node)  # ValueError listing the known names
        self._deadlines_stale = True
        return {"faults": {str(esc.node_id): sorted(esc.faults) for esc in self._escs}}

    def _cmd_faults(self, req: dict, reply: Reply) -> dict:
        return {"faults": {f.name: {"rules": list(f.rules), "description": f.description, "kind": f.kind}
                           for f in _faults.FAULTS.values()}}

    def _cmd_bitrate(self, req: dict, reply: Reply) -> dict:
        value = req.get("bitrate")
        if isinstance(value, bool) or not isinstance(value, int) or value <= 0:
            raise ValueError(f"bitrate must be a positive integer (bit/s), not {value!r}")
        self.bitrate = value
        self.can.set_bitrate(value, time.monotonic())  # the host's adapter moved: it listens at the new rate from now
        return {"bitrate": value}

    # ------------------------------------------------------------------ bus faults (:mod:`.hub_can`)
    def _cmd_bus_fault(self, req: dict, reply: Reply) -> dict | None:
        """``kind`` for ``seconds`` (answered at its end), or ``on``: true (until ``on``: false ends it, a relay)."""
        kind, seconds, on = req.get("kind"), req.get("seconds"), req.get("on")
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {', '.join(KINDS)}, not {kind!r}")
        if (seconds is None) == (on is None):
            raise ValueError("give seconds (a fault for that long) or on: true / false (a relay closed, opened)")
        now = time.monotonic()
        self._emit_due(now)  # what fell due before it went out before it
        if on is not None:
            if not isinstance(on, bool):
                raise ValueError(f"'on' must be true or false, not {on!r}")
            if not on:
                fault = self.can.stop(now)
                return {"kind": kind, "ended": now + self.offset, "was_on": fault is not None}
            fault = self.can.start(kind, now)
            return {"kind": kind, "started": fault.start + self.offset}
        if isinstance(seconds, bool) or not isinstance(seconds, (int, float)):
            raise ValueError(f"seconds must be a number, not {seconds!r}")
        fault = self.can.start(kind, now, float(seconds))
        answer = {"ok": True, "kind": kind, "started": fault.start + self.offset, "ended": fault.end + self.offset}
        self._bus_waiters.append((fault.end, False, lambda: reply(answer)))
        return None  # answered at its end (bus time: the stamps' clock)

    def _cmd_bus_settle(self, req: dict, reply: Reply) -> dict | None:
        """Answered once every ESC's controller is back from a fault (``settled`` true) or after ``within`` s."""
        within = req.get("within", 0.0)
        if isinstance(within, bool) or not isinstance(within, (int, float)) or not 0 <= within <= 60:
            raise ValueError(f"within must be a number of seconds 0..60, not {within!r}")
        self._bus_waiters.append((time.monotonic() + within, True,
                                  lambda: reply({"ok": True, **self._bus_state(time.monotonic())})))
        return None

    def _can_poll(self, now: float) -> None:
        """The bus fault's work due by ``now`` (recoveries, held frames sent, reboots) and the answers due."""
        sent, rebooted = self.can.poll(now)
        for handle, err in self.can.host_poll(now):  # the host adapter's error frames, to that handle alone
            if self._socketcand is not None and handle in self._socketcand.conns:
                self._socketcand.write(handle, fmt_error(err.can_id, err.timestamp + self.offset))
        if sent:
            for esc, w in sent:
                self._transmit(esc, [w])
            for esc, w in sent:  # the other ESCs hear them too
                self.bench.deliver(w, w.timestamp, esc.state.bitrate, sender=esc)
        for esc, t in rebooted:  # fault busoff_recovery_resets: the firmware resets at its recovery
            esc.power_off(t)
            esc.power_on(t)
        if sent or rebooted:
            self.bench.touch()
            self._deadlines_stale = True
        settled = self.can.settled()
        waiting, self._bus_waiters = self._bus_waiters, []
        for by, settle, answer in waiting:  # a fault's end; a settle once the bus is back, or by its limit
            if by <= now or (settle and settled):
                answer()
            else:
                self._bus_waiters.append((by, settle, answer))

    def _bus_state(self, now: float) -> dict:
        return {"settled": self.can.settled(), "bus_fault": self.can.describe(now),
                "escs": {str(esc.node_id): self.can.state(esc) for esc in self._escs}}

    def _cmd_stats(self, req: dict, reply: Reply) -> dict:
        out = {"lateness": summary(self.lateness), "wakeup": summary(self.wakeup), "counters": dict(self.counters)}
        if req.get("reset"):
            self.lateness.reset()
            self.wakeup.reset()
        return out

    def _cmd_save(self, req: dict, reply: Reply) -> dict:
        self.bench.persist()
        return {"flash": None if self.bench.flash is None else str(self.bench.flash.path)}

    def _cmd_stop(self, req: dict, reply: Reply) -> dict:
        self._stopping = True
        return {"stopping": True}


def _addr(address: tuple[str, int] | None) -> str | None:
    return None if address is None else f"{address[0]}:{address[1]}"
