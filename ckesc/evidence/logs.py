"""Reading captures for the bus rules: frames as plain tuples, damaged records reported, never raised.

    for can_id, data, timestamp, extended, remote, error, own in read_capture(path, on_bad=report):
        ...

``on_bad(line, text, reason)`` hears every record that could not be read (``line`` is its line number
in a text format, ``None`` where a binary format has none). Nothing is lost silently: a line is a
frame, a blank or comment line, or a reported bad record.

candump ``-L`` logs (``.log``) are read by :func:`read_candump`, everything else by python-can's
``can.LogReader`` (``.asc``, ``.blf``, ``.trc``, ``.csv``, ``.mf4``, ``.db``, compressed ``.gz``).
Why a reader of our own for candump: python-can's ``CanutilsLogReader`` builds a ``can.Message`` per
line: 4.1 us of CPU per frame (246k frames/s, ``benchmarks/checklog.py`` on this project's machine),
which with the rules' ~2.1 us leaves ``ckesc check-log`` at its 160k frames/s target with no margin (and
at well under half of it in wall time on a loaded machine); it also stops at the first bad line, without
its number. Splitting the common line form ``(ts) iface 1F4E5205#DATA`` ourselves costs 1.7 us (580k
frames/s): check-log reaches 255k-272k frames/s of CPU time. Every other form (display form, remote and
error frames, CAN FD, bare ``ID#DATA``, damage) goes through :func:`ckesc.evidence.candump.parse_candump`, which
follows candump's conventions and names what is wrong with a line.
"""

from __future__ import annotations

import os
from typing import Callable, Iterator

import can

from .candump import CandumpError, parse_candump

FrameTuple = tuple  # (can_id, data, timestamp, extended, remote, error, own)
OnBad = Callable[[int | None, str, str], None]
#: ``on_truncated(read, declared, detail)``: the file is shorter than its own header says
OnTruncated = Callable[[int, int, str], None]

_CAN_EXT_MAX = 0x1FFFFFFF


def capture_format(path: str) -> str:
    """``log`` for candump files, else the suffix python-can's LogReader goes by (``asc``, ``blf``, ...)."""
    name = os.path.basename(path).lower()
    if name.endswith(".gz"):
        name = name[:-3]
    return name.rsplit(".", 1)[-1] if "." in name else ""


def read_capture(path: str, on_bad: OnBad, on_truncated: OnTruncated | None = None) -> Iterator[FrameTuple]:
    """Every frame of the capture at ``path`` in file order. A format whose header states its own size
    (BLF) is checked against it: ``on_truncated`` hears a file cut short (a copy that stopped, a logger
    that lost power), with how many frames were read of the objects the header declares."""
    if capture_format(path) == "log" and not path.lower().endswith(".gz"):
        return read_candump(path, on_bad)
    return read_python_can(path, on_bad, on_truncated)


def read_candump(path: str, on_bad: OnBad) -> Iterator[FrameTuple]:
    """A candump log, line by line (see the module docstring for why not python-can's reader)."""
    fromhex = bytes.fromhex
    with open(path, encoding="utf-8", errors="replace") as stream:  # undecodable bytes fail their line only
        for number, line in enumerate(stream, 1):
            p = line.split()
            n = len(p)
            if (n == 3 or (n == 4 and p[3] in ("R", "T"))) and p[0][:1] == "(":
                frame = p[2]
                if len(frame) > 8 and frame[8] == "#" and frame[9:10] not in ("R", "#", ""):
                    try:
                        ts = float(p[0][1:-1])
                        can_id = int(frame[:8], 16)
                        data = fromhex(frame[9:])
                    except ValueError:
                        pass  # the exact parser below says what is wrong
                    else:
                        if can_id <= _CAN_EXT_MAX and len(data) <= 8 and ts - ts == 0 and frame[:8].isalnum():
                            yield can_id, data, ts, True, False, False, n == 4 and p[3] == "T"
                            continue
            try:
                parsed = parse_candump(line)
            except CandumpError as exc:
                on_bad(number, line.rstrip("\r\n"), str(exc))
                continue
            if parsed is None:
                continue
            msg = parsed.msg
            if parsed.timestamp is None:
                on_bad(number, line.rstrip("\r\n"), "no timestamp: the rules need when each frame was on the bus")
                continue
            if msg.is_fd or len(msg.data) > 8:
                on_bad(number, line.rstrip("\r\n"), "CAN FD frame: the protocol uses classic CAN frames")
                continue
            yield (msg.arbitration_id, bytes(msg.data), msg.timestamp, msg.is_extended_id, msg.is_remote_frame,
                   msg.is_error_frame, not msg.is_rx)


def read_python_can(path: str, on_bad: OnBad, on_truncated: OnTruncated | None = None) -> Iterator[FrameTuple]:
    """Any format python-can reads. A reader that fails mid-file cannot go on: the failure is reported
    (after how many frames) and the frames before it are kept."""
    declared: tuple[int, int] | None = None
    count = 0
    try:
        reader = can.LogReader(path)
    except Exception as exc:  # noqa: BLE001 - an unknown suffix, an unreadable file: reported, not raised
        on_bad(None, path, f"python-can cannot read it: {exc}")
        return
    declared = _blf_declared(reader)
    try:
        with reader:
            for msg in reader:
                if msg.is_fd or len(msg.data) > 8:
                    on_bad(None, str(msg), f"frame {count + 1}: CAN FD frame: the protocol uses classic CAN frames")
                    continue
                count += 1
                yield (msg.arbitration_id, bytes(msg.data), msg.timestamp, msg.is_extended_id, msg.is_remote_frame,
                       msg.is_error_frame, not msg.is_rx)
    except Exception as exc:  # noqa: BLE001 - damage in a binary file: keep what was read, say where it stopped
        on_bad(None, "", f"reading stopped after frame {count}: {type(exc).__name__}: {exc}")
    if declared is not None and on_truncated is not None:
        objects, size = declared
        actual = os.path.getsize(path)
        if size and actual < size:  # a count alone proves nothing: a BLF may hold objects other than frames
            on_truncated(count, objects, f"{count} frames read of the {objects} objects its BLF header declares; the "
                                         f"file has {actual} of the {size} bytes the header declares")


def _blf_declared(reader: can.LogReader) -> tuple[int, int] | None:
    """(object count, file size) a BLF file's header declares (0: not filled in by its writer)."""
    if isinstance(reader, can.BLFReader):
        return int(getattr(reader, "object_count", 0) or 0), int(getattr(reader, "file_size", 0) or 0)
    return None
