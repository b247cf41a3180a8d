"""The client of the real-time emulator's control channel (``ckesc emulate --control``; the requests
and answers are described in :mod:`.realtime`). ``ckesc control`` wraps :func:`control_request`."""

from __future__ import annotations

import errno
import json
import socket

LOCALHOST = "127.0.0.1"


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
