"""The real-time emulator's control channel (``ckesc emulate --control PORT``, :mod:`.realtime`), for
harness power switching and fault injection.

Line-based JSON on 127.0.0.1: one request object per line, one answer object per line, on a
connection that may stay open. Every answer has ``"ok": true`` or ``"ok": false`` with
``"error"``. Requests:

``{"cmd": "status"}``
    power state, bit rate, uptime, clients, frame counts, lateness summary, and per ESC: slot,
    node id, powered, ready, bitrate, reporting state, faults, counters, power-up count.
``{"cmd": "power", "action": "off" | "on" | "cycle", "off_time": 1.0}``
    ``cycle`` answers once power is back on (after ``off_time`` seconds). Power-off writes the
    flash file.
``{"cmd": "fault", "name": "answer_late", "on": true, "node": 3}``
    ``node`` optional (default: every ESC). An unknown name is an error listing the known ones.
``{"cmd": "faults"}``: the known faults with their rules and descriptions.
``{"cmd": "bitrate", "bitrate": 250000}``: the emulated bus's bit rate from now on.
``{"cmd": "bus_fault", "kind": "short" | "other_bitrate", "seconds": 0.5}``
    a bus fault on the hub (:mod:`.hub_can`) for that long, answered at its end with ``started`` and ``ended`` in bus
    time; ``"on": true`` instead of ``seconds`` starts one that lasts until ``"on": false`` (a relay).
``{"cmd": "bus_settle", "within": 0.5}``: answered once every ESC's controller is back from a bus fault, or after
    ``within`` seconds: ``settled``, the fault on, each ESC's controller.
``{"cmd": "stats", "reset": false}``: the lateness summary (and start a new one).
``{"cmd": "save"}``: write the flash file now.
``{"cmd": "stop"}``: stop the emulator (power off, flash saved), as SIGTERM does.

The server side is :class:`ControlServer` (the lines) and :func:`dispatch` (a request to its command's
handler, the answer or the error back); the handlers are the emulator's (:class:`.realtime.RealtimeEmulator`,
which runs :func:`dispatch` in its loop thread). :func:`control_request` is the client; ``ckesc control``
wraps it.
"""

from __future__ import annotations

import errno
import json
import socket
from typing import Any, Callable, Mapping

from .tcp import LOCALHOST, Conn, TcpServer

Reply = Callable[[dict], None]
#: a command's handler: (request, reply) -> the answer's fields, or None when it calls ``reply`` itself later
Handler = Callable[[dict, Reply], "dict | None"]


# ---------------------------------------------------------------------------------------------------
# the server


class ControlServer(TcpServer):
    """The control connections. Each request line goes to ``submit(req, reply)``, which is to have
    :func:`dispatch` run it in the loop thread; ``reply`` writes the answer line if the connection is
    still open."""

    def __init__(self, port: int, *, submit: Callable[[Any, Reply], None], log: Callable[[str], None]) -> None:
        super().__init__(port, log)
        self._submit = submit

    def received(self, conn: Conn, now: float) -> None:
        while True:
            nl = conn.inbuf.find(b"\n")
            if nl < 0:
                return
            line = bytes(conn.inbuf[:nl]).strip()
            del conn.inbuf[: nl + 1]
            if not line:
                continue

            def reply(answer: dict, conn: Conn = conn) -> None:
                if conn in self.conns:
                    self.write(conn, json.dumps(answer).encode() + b"\n")

            try:
                req = json.loads(line)
            except ValueError as exc:
                reply({"ok": False, "error": f"not a JSON object: {exc}"})
                continue
            self._submit(req, reply)

    def send_pending(self) -> None:
        """Answers already queued (e.g. to "stop") go out, blocking briefly: the loop is ending."""
        for conn in self.conns:
            try:
                conn.sock.setblocking(True)
                conn.sock.settimeout(0.5)
                conn.sock.sendall(conn.out)
            except OSError:
                pass


def dispatch(commands: Mapping[str, Handler], req: Any, reply: Reply) -> None:
    """One control request: ``reply`` is called once (maybe later: power cycle)."""
    try:
        if not isinstance(req, dict):
            raise ValueError("a request is a JSON object such as {\"cmd\": \"status\"}")
        cmd = req.get("cmd")
        handler = commands.get(cmd)  # type: ignore[arg-type]
        if handler is None:
            raise ValueError(f"unknown command {cmd!r}; known: {', '.join(commands)}")
        answer = handler(req, reply)
    except (ValueError, TypeError, KeyError) as exc:
        text = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        reply({"ok": False, "error": str(text)})
        return
    if answer is not None:
        reply({"ok": True, **answer})


# ---------------------------------------------------------------------------------------------------
# the client


class ControlError(RuntimeError):
    """The emulator is not reachable, or it answered ``ok: false``; the message says which."""

    def __init__(self, message: str, *, unreachable: bool = False) -> None:
        super().__init__(message)
        self.unreachable = unreachable


def control_request(port: int, req: dict, *, host: str = LOCALHOST, timeout: float | None = None) -> dict:
    """Send one request to a running emulator's control port and return its answer (``ok`` true).
    Raises :class:`ControlError` when nothing listens there, the connection fails, or the answer is an error."""
    if timeout is None:
        timeout = 10.0 + float(req.get("off_time") or 0.0)
    where = f"{host}:{port}"
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except ConnectionRefusedError:
        raise ControlError(f"no emulator is running with its control channel on {where} (connection refused); "
                           f"start one with 'ckesc emulate --control {port} ...'", unreachable=True) from None
    except OSError as exc:
        raise ControlError(f"cannot reach the emulator's control channel on {where}: {exc.strerror or exc}",
                           unreachable=True) from None
    with sock:
        try:
            sock.sendall(json.dumps(req).encode() + b"\n")
            data = bytearray()
            while b"\n" not in data:
                chunk = sock.recv(65536)
                if not chunk:
                    break
                data += chunk
        except TimeoutError:
            raise ControlError(f"no answer from the emulator on {where} within {timeout} s", unreachable=True) from None
        except OSError as exc:
            if exc.errno in (errno.ECONNRESET, errno.EPIPE):
                raise ControlError(f"the emulator on {where} closed the connection", unreachable=True) from None
            raise ControlError(f"control connection to {where} failed: {exc}", unreachable=True) from None
    line = bytes(data).split(b"\n", 1)[0]
    if not line:
        raise ControlError(f"the emulator on {where} closed the connection without answering", unreachable=True)
    try:
        answer = json.loads(line)
    except ValueError:
        raise ControlError(f"{where} answered something that is not JSON: {line[:200]!r}") from None
    if not isinstance(answer, dict) or not answer.get("ok"):
        error = answer.get("error") if isinstance(answer, dict) else answer
        raise ControlError(str(error))
    return answer
