"""The real-time emulator's socketcand hub (``ckesc emulate --socketcand PORT``, :mod:`.realtime`).

The socketcand ASCII protocol on 127.0.0.1, as a hub: python-can's stock
``can.Bus(interface="socketcand", host="127.0.0.1", port=P, channel="can0")`` connects.
Handshake ``< hi >``, ``< open NAME >`` (any name) -> ``< ok >``, ``< rawmode >`` -> ``< ok >``;
then frames go out as ``< frame ID SEC.USEC DATA >`` (ID 8 hex digits for 29-bit ids, 3 for
11-bit; DATA hex, no spaces) and come in as ``< send ID LEN B0 B1 ... >``. A client gets no
frames during the first 50 ms after its rawmode ``< ok >`` (python-can reads each handshake
reply with a single ``recv()``), unless it sends a frame first. Every frame a client sends is
echoed to every client, the sender included, stamped with its arrival time, so that a client
can measure answer delays from bus timestamps at both ends (set ``echo_own=False`` for
SocketCAN's default, where the sender does not see its own frames). ``< echo >`` is answered;
other commands are ignored. Classic CAN only.

Which clients hear each other (``handles``, :data:`HANDLES`): the name a client opens is its adapter. With
``shared`` (the default) every client hears every other client's frames, as SocketCAN's loopback, socketcand and
python-can's ``virtual`` bus let them. With ``separate`` the clients that opened the same name are handles of one
adapter and do not hear each other's frames (most USB adapters: a frame one handle sends reaches the bus, and the
other handles of the adapter never receive it); a client that opened another name (the DUT's own connection, say
``esc``) is another node on the bus and hears them all. With ``one`` a name is opened by one client at a time, as
adapters that allow one handle: a second ``< open NAME >`` is refused with ``< error >`` (python-can's client raises
``CanError``) and its connection closed.

:class:`SocketcandServer` speaks the protocol; the scheduler owns it: it hands each frame a client
sends to the ESCs (``on_frame``) and decides which frames go out to the clients, and with which stamp
(:meth:`SocketcandServer.to_clients` with :func:`fmt_frame`).
"""

from __future__ import annotations

import time
from typing import Any, Callable

import can

from ..protocol.frame import WireFrame
from .tcp import Conn, TcpServer

RAWMODE_QUIET_S = 0.050  # no frames to a client for this long after its rawmode "< ok >"
#: which clients hear each other (the module docstring): every one; not the handles of one adapter; one handle each
HANDLES = ("shared", "separate", "one")


def fmt_frame(wire: Any, stamp: float) -> bytes:
    """``< frame ID SEC.USEC DATA >`` as socketcand writes it."""
    sec, usec = divmod(round(stamp * 1e6), 1_000_000)
    can_id = f"{wire.arbitration_id & 0x1FFFFFFF:08X}" if wire.is_extended_id else f"{wire.arbitration_id & 0x7FF:03X}"
    return f"< frame {can_id} {sec}.{usec:06d} {bytes(wire.data).hex().upper()} >".encode("ascii")


def fmt_error(error_class: int, stamp: float) -> bytes:
    """``< error CLASS SEC.USEC >``, as socketcand passes on an error frame of its SocketCAN socket: the class (the
    id without ``CAN_ERR_FLAG``) and its stamp; socketcand carries none of its data bytes (python-can's client makes
    an ``is_error_frame`` message of it with that class as its id and one zero byte)."""
    sec, usec = divmod(round(stamp * 1e6), 1_000_000)
    return f"< error {error_class:03X} {sec}.{usec:06d} >".encode("ascii")


def _parse_send(words: list[str]) -> WireFrame | None:
    """``send ID LEN B0 B1 ...`` (python-can writes bytes without zero padding) -> a frame, None if malformed."""
    try:
        id_text = words[1]
        can_id = int(id_text, 16)
        length = int(words[2], 16)
        data = bytes(int(b, 16) for b in words[3:])
    except (IndexError, ValueError):
        return None
    extended = len(id_text) > 3 or can_id > 0x7FF
    if length != len(data) or length > 8 or can_id > 0x1FFFFFFF:
        return None
    return WireFrame(can_id, data, 0.0, is_extended_id=extended)


class SocketcandServer(TcpServer):
    """The socketcand clients. A frame a client sends goes to ``on_frame(t, msg, wire, conn)`` (``t``: the
    read time); ``counters`` (the scheduler's) counts ``clients`` accepted and ``rx_malformed`` frames."""

    def __init__(
        self,
        port: int,
        *,
        on_frame: Callable[[float, can.Message, WireFrame, Conn], None],
        counters: dict[str, int],
        log: Callable[[str], None],
        handles: str = "shared",
        echo_own: bool = True,
        on_listen: Callable[[Conn, float | None], None] = lambda conn, since: None,
    ) -> None:
        if handles not in HANDLES:
            raise ValueError(f"handles must be one of {', '.join(HANDLES)}, not {handles!r}")
        super().__init__(port, log)
        self._on_frame = on_frame
        self._counters = counters
        self.handles = handles
        self.echo_own = echo_own
        self._on_listen = on_listen

    def accepted(self, conn: Conn) -> None:
        self._counters["clients"] += 1
        self.write(conn, b"< hi >")

    def received(self, conn: Conn, now: float) -> None:
        buf = conn.inbuf
        while True:
            start = buf.find(b"<")
            if start < 0:
                buf.clear()
                return
            end = buf.find(b">", start)
            if end < 0:
                del buf[:start]
                return
            words = buf[start + 1 : end].decode("ascii", "replace").split()
            del buf[: end + 1]
            if not words:
                continue
            cmd = words[0]
            if cmd == "send" and conn.state in ("open", "raw"):
                wire = _parse_send(words)
                if wire is None:
                    self._counters["rx_malformed"] += 1
                    continue
                conn.rx += 1
                if conn.quiet_until:
                    self._on_listen(conn, now)
                conn.quiet_until = 0.0  # it has read our "< ok >": frames may flow
                msg = can.Message(arbitration_id=wire.arbitration_id, is_extended_id=wire.is_extended_id, data=wire.data)
                self._on_frame(now, msg, wire, conn)
            elif cmd == "open" and conn.state == "hi" and len(words) == 2:
                if self.handles == "one" and any(c.channel == words[1] for c in self.conns if c is not conn):
                    self._counters["refused"] = self._counters.get("refused", 0) + 1
                    self._log(f"{conn.peer}: {words[1]} is open on another handle (--handles one); refused")
                    self.write(conn, b"< error >")
                    self.drop(conn)
                    return
                conn.state = "open"
                conn.channel = words[1]
                self.write(conn, b"< ok >")
            elif cmd == "rawmode" and conn.state in ("open", "raw"):
                conn.state = "raw"
                conn.quiet_until = time.monotonic() + RAWMODE_QUIET_S
                self._on_listen(conn, conn.quiet_until)  # it acknowledges from when it can take frames
                self.write(conn, b"< ok >")
            elif cmd == "echo":
                self.write(conn, b"< echo >")
            # anything else (bcmmode commands, filters, ...) is ignored: python-can never sends it,
            # and an "< error >" line would be read by its client as a CAN error frame

    def drop(self, conn: Conn) -> None:
        super().drop(conn)
        self._on_listen(conn, None)

    def to_clients(self, data: bytes, now: float, origin: Conn | None = None) -> None:
        """``data`` (formatted frames) to every client in raw mode that hears it, unless it is still quiet: a frame of
        the bus's own (``origin`` None) to all; a client's to the others (but the handles of its own adapter where
        they are not ``shared``) and back to itself where :attr:`echo_own`."""
        for c in list(self.conns):
            if c.state != "raw":
                continue
            if origin is not None:
                if c is origin:
                    if not self.echo_own:
                        continue
                elif self.handles != "shared" and c.channel == origin.channel:
                    continue
            if now < c.quiet_until:
                c.dropped += 1
                continue
            c.tx += 1
            self.write(c, data)
