"""The TCP side the real-time emulator's two servers share: the socketcand hub (:mod:`.socketcand`) and
the control channel (:mod:`.control`). A :class:`TcpServer` is a non-blocking listening socket on
127.0.0.1 and the connections it accepted, each with an input buffer and an output backlog; it does no
waiting of its own. The scheduler (:mod:`.realtime`) puts the server (readable: a connection to accept)
and its connections in its ``select()`` and calls :meth:`TcpServer.accept`, :meth:`TcpServer.read` and
:meth:`TcpServer.flush`; a subclass says what a connection's input means (:meth:`TcpServer.received`).
"""

from __future__ import annotations

import socket
from typing import Callable

LOCALHOST = "127.0.0.1"
MAX_CLIENT_BACKLOG = 4 << 20  # bytes queued for a client that does not read: it is dropped
MAX_LINE = 1 << 16  # longest control line / socketcand command accepted


def listen(port: int) -> socket.socket:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        s.bind((LOCALHOST, port))
        s.listen(16)
        s.setblocking(False)
    except OSError:
        s.close()
        raise
    return s


class Conn:
    """A TCP connection served by the loop: input buffer, output backlog."""

    __slots__ = ("sock", "server", "peer", "inbuf", "out", "state", "quiet_until", "rx", "tx", "dropped", "channel")

    def __init__(self, sock: socket.socket, server: TcpServer) -> None:
        self.sock = sock
        self.server = server
        try:
            host, port = sock.getpeername()[:2]
            self.peer = f"{host}:{port}"
        except OSError:
            self.peer = "?"
        self.inbuf = bytearray()
        self.out = bytearray()
        self.state = "hi"  # socketcand: hi -> open -> raw
        self.quiet_until = 0.0
        self.rx = self.tx = self.dropped = 0
        self.channel = ""  # socketcand: the name the client opened (its adapter, where handles are told apart)

    def fileno(self) -> int:
        return self.sock.fileno()


class TcpServer:
    """A listener on 127.0.0.1 (opened here: a port in use raises ``OSError``) and its connections."""

    def __init__(self, port: int, log: Callable[[str], None]) -> None:
        self.listener = listen(port)
        self.conns: list[Conn] = []
        self._log = log

    @property
    def address(self) -> tuple[str, int]:
        return self.listener.getsockname()[:2]

    def fileno(self) -> int:
        return self.listener.fileno()

    def received(self, conn: Conn, now: float) -> None:
        """New input in ``conn.inbuf`` (read at ``now``): consume what is complete."""
        raise NotImplementedError

    def accepted(self, conn: Conn) -> None:
        """A new connection, already in :attr:`conns`."""

    def accept(self) -> None:
        try:
            sock, _ = self.listener.accept()
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self._log(f"accept failed: {exc}")
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn = Conn(sock, self)
        self.conns.append(conn)
        self.accepted(conn)

    def read(self, conn: Conn, now: float) -> None:
        try:
            data = conn.sock.recv(65536)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            data = b""
        if not data:
            self.drop(conn)
            return
        conn.inbuf += data
        self.received(conn, now)
        if len(conn.inbuf) > MAX_LINE:
            self._log(f"{conn.peer}: more than {MAX_LINE} bytes without a complete command; dropped")
            self.drop(conn)

    def write(self, conn: Conn, data: bytes) -> None:
        conn.out += data
        self.flush(conn)

    def flush(self, conn: Conn) -> None:
        if not conn.out:
            return
        try:
            n = conn.sock.send(conn.out)
        except (BlockingIOError, InterruptedError):
            n = 0
        except OSError:
            self.drop(conn)
            return
        del conn.out[:n]
        if len(conn.out) > MAX_CLIENT_BACKLOG:
            self._log(f"{conn.peer}: does not read its frames ({len(conn.out)} bytes queued); dropped")
            self.drop(conn)

    def drop(self, conn: Conn) -> None:
        if conn in self.conns:
            self.conns.remove(conn)
        try:
            conn.sock.close()
        except OSError:
            pass

    def close(self) -> None:
        """Close every connection, then the listener."""
        for conn in list(self.conns):
            self.drop(conn)
        self.listener.close()
