"""candump lines as frames: the reader behind ``ckesc decode`` and :func:`ckesc.evidence.logs.read_candump`.

:func:`parse_candump` reads one line of candump output (``candump -L`` log, display form, bare
``ID#DATA``) into a :class:`can.Message`, raising :class:`CandumpError` with a machine-stable
``reason``; :func:`decode_lines` decodes a stream of lines into JSON-able dicts, one per frame line.
"""

from __future__ import annotations

import re
from typing import Any, Iterable, Iterator, NamedTuple

import can

from ..protocol.errors import DecodeError
from ..protocol.frame import Decoder

# Hand parsing, not can.io.CanutilsLogReader: the reader iterates a whole file and raises on the first
# bad line (no line number, nothing after it is read), needs the "(ts) iface ID#DATA" form (bare
# "ID#DATA" as cansend takes it fails its three-way split), reads odd hex "ABC" as the bytes AB 0C
# without a word, and flags only bus-error frames as error frames. We follow its conventions where
# they are candump's (an id of more than 3 hex digits is extended, "ID#R" is a remote frame, "##"
# opens a CAN FD frame, a trailing R/T is the direction) and build the same can.Message, line by line.

CAN_ERR_FLAG = 0x20000000  # linux/can.h; candump prints error frames with it in the 8-digit id
_HEX = frozenset("0123456789abcdefABCDEF")

#: candump's default display form: "[(ts)]  can0  1F4E5205   [7]  34 12 E8 03 01 81 C0"
_DISPLAY = re.compile(r"^(?:\((?P<ts>[^)]*)\)\s+)?(?P<iface>\S+)\s+(?P<id>[0-9A-Fa-f]+)\s+\[(?P<dlc>\d+)\]\s*(?P<rest>.*)$")


class CandumpError(ValueError):
    """A line that is not a CAN frame in any candump form; ``reason`` is machine-stable."""

    def __init__(self, message: str, reason: str = "not-candump") -> None:
        super().__init__(message)
        self.reason = reason


class CandumpLine(NamedTuple):
    msg: can.Message
    timestamp: float | None  # None when the line has none (the message's is then 0.0)
    channel: str | None


def parse_candump(line: str) -> CandumpLine | None:
    """One line of candump output as a :class:`can.Message`; ``None`` for blank and ``#`` lines.

    Accepts ``candump -L`` log lines ``(1700000000.123456) can0 1F4E5205#3412E8030181C0`` (with an
    optional trailing ``R``/``T``), bare ``1F4E5205#...`` (cansend syntax, ``.`` separators allowed)
    and candump's display form ``can0  1F4E5205   [7]  34 12 ...``. Raises :class:`CandumpError`.
    """
    text = line.strip()
    if not text or text.startswith("#"):
        return None
    tokens = text.split()
    if "#" not in text or " [" in text:  # a -L line never has " ["; a display line may have '#' in its ASCII column
        return _parse_display(text)
    timestamp = channel = None
    is_rx = True
    if tokens[0].startswith("("):
        timestamp = _timestamp(tokens.pop(0), text)
    if len(tokens) >= 2 and tokens[-1] in ("R", "T", "r", "t"):
        is_rx = tokens.pop().upper() == "R"
    if len(tokens) == 2 and "#" not in tokens[0]:
        channel = tokens.pop(0)
    if len(tokens) != 1:
        raise CandumpError(f"not a candump line: {text!r}")
    return CandumpLine(_frame(tokens[0], timestamp, channel, is_rx), timestamp, channel)


def _timestamp(token: str, text: str) -> float:
    if not (token.startswith("(") and token.endswith(")")):
        raise CandumpError(f"timestamp {token!r} is not '(seconds)': {text!r}")
    try:
        return float(token[1:-1])
    except ValueError:
        raise CandumpError(f"timestamp {token!r} is not a number", "bad-timestamp") from None


def _can_id(id_text: str) -> tuple[int, bool]:
    if not id_text or not set(id_text) <= _HEX or len(id_text) > 8:
        raise CandumpError(f"CAN id {id_text!r} is not 1..8 hex digits", "bad-id")
    can_id = int(id_text, 16)
    if len(id_text) <= 3 and can_id > 0x7FF:
        raise CandumpError(f"standard CAN id 0x{can_id:03X} does not fit 11 bits", "bad-id")
    return can_id, len(id_text) > 3  # candump prints 3 digits for 11-bit ids and 8 for 29-bit ones


def _message(can_id: int, extended: bool, data: bytes, timestamp, channel, *, remote=False, dlc=None, is_rx=True) -> can.Message:
    if extended and can_id & CAN_ERR_FLAG:
        return can.Message(timestamp=timestamp or 0.0, arbitration_id=can_id & 0x1FFFFFFF, is_error_frame=True, data=data, channel=channel)
    return can.Message(
        timestamp=timestamp or 0.0,
        arbitration_id=can_id,
        is_extended_id=extended,
        is_remote_frame=remote,
        data=None if remote else data,
        dlc=dlc,
        channel=channel,
        is_rx=is_rx,
    )


def _frame(token: str, timestamp: float | None, channel: str | None, is_rx: bool) -> can.Message:
    id_text, _, data_text = token.partition("#")
    can_id, extended = _can_id(id_text)
    if data_text.startswith("#"):
        raise CandumpError("CAN FD frame (ID##...): the protocol uses classic CAN 2.0B frames (4.1)", "not-classic-can")
    if data_text[:1] in ("R", "r"):
        dlc_text = data_text[1:]
        if dlc_text and not (dlc_text.isdigit() and int(dlc_text) <= 8):
            raise CandumpError(f"remote frame length {dlc_text!r} is not 0..8", "bad-data")
        return _message(can_id, extended, b"", timestamp, channel, remote=True, dlc=int(dlc_text or 0), is_rx=is_rx)
    hex_text = data_text.replace(".", "")
    if not set(hex_text) <= _HEX:
        raise CandumpError(f"data {data_text!r} is not hex", "bad-data")
    if len(hex_text) % 2:
        raise CandumpError(f"data {data_text!r} has an odd number of hex digits ({len(hex_text)})", "odd-hex")
    return _message(can_id, extended, bytes.fromhex(hex_text), timestamp, channel, is_rx=is_rx)


def _parse_display(text: str) -> CandumpLine:
    m = _DISPLAY.match(text)
    if m is None:
        raise CandumpError(f"not a candump line: {text!r}")
    timestamp = _timestamp(f"({m['ts']})", text) if m["ts"] is not None else None
    can_id, extended = _can_id(m["id"])
    dlc = int(m["dlc"])
    rest = m["rest"]
    if rest.startswith("remote request"):
        msg = _message(can_id, extended, b"", timestamp, m["iface"], remote=True, dlc=min(dlc, 8))
        return CandumpLine(msg, timestamp, m["iface"])
    data = []
    for token in rest.split():
        if len(token) != 2 or not set(token) <= _HEX:
            break  # the ASCII column of candump -a, or ERRORFRAME details
        data.append(int(token, 16))
    if len(data) != dlc:
        raise CandumpError(f"[{dlc}] announces {dlc} data bytes, the line has {len(data)}", "bad-data")
    return CandumpLine(_message(can_id, extended, bytes(data), timestamp, m["iface"]), timestamp, m["iface"])


def decode_lines(lines: Iterable[str], decoder: Decoder | None = None) -> Iterator[dict[str, Any]]:
    """One JSON-able dict per frame line (blank and comment lines give none), with ``line`` numbers.
    A line that does not decode gives ``{"error", "line", "reason", "frame", "text"}``."""
    decoder = decoder or Decoder()
    for number, raw in enumerate(lines, 1):
        text = raw.rstrip("\r\n")
        try:
            parsed = parse_candump(text)
            if parsed is None:
                continue
            frame = decoder.decode(parsed.msg)
        except CandumpError as exc:
            yield {"error": str(exc), "line": number, "reason": exc.reason, "frame": None, "text": text}
            continue
        except DecodeError as exc:
            yield {"error": str(exc), "line": number, "reason": exc.reason, "frame": exc.frame, "text": text}
            continue
        out = frame.to_json()
        out["timestamp"] = parsed.timestamp
        out["channel"] = parsed.channel
        out["can_id"] = f"{parsed.msg.arbitration_id:08X}"
        out["data"] = frame.data.hex().upper()
        out["line"] = number
        yield out
