"""The real-time emulator's control commands (``status``, ``power``, ``fault``, ``faults``, ``bitrate``,
``stats``, ``save``, ``stop``; the channel and its requests: :mod:`.control`): the handlers a
:class:`.realtime.RealtimeEmulator` runs in its loop thread, kept here as a mixin so that the emulator's
module holds its scheduling loop and IO."""

from __future__ import annotations

import time
from typing import Any

from . import faults as _faults
from .control import Reply
from .realtime_timing import summary


class ControlCommands:
    """Mixin of :class:`.realtime.RealtimeEmulator`: its ``_cmd_*`` handlers (it provides the bench, the
    ESCs, the statistics and the timers they use)."""

    # attributes the emulator provides
    bench: Any
    _escs: list
    _stopping: bool

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
        return {"bitrate": value}

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
