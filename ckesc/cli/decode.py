"""``ckesc decode``: candump lines (FILE or stdin) to JSON, one object per frame line."""

from __future__ import annotations

import argparse
import io
import json
import sys
from typing import IO, Callable

from ..evidence.candump import decode_lines
from ..protocol.frame import Decoder
from ..reporting.exits import ExitStatus
from .common import UsageError


def _open_input(path: str | None) -> tuple[IO[str], Callable[[], None]]:
    """The text stream to read and how to let go of it (stdin is detached, not closed)."""
    if path is None or path == "-":
        buffer = getattr(sys.stdin, "buffer", None)
        if buffer is None:  # already a text stream (tests, embedding)
            return sys.stdin, lambda: None
        # undecodable bytes become U+FFFD and that line fails to parse, instead of a UnicodeDecodeError
        wrapper = io.TextIOWrapper(buffer, encoding="utf-8", errors="replace")
        return wrapper, wrapper.detach
    try:
        with open(path, "rb") as probe:
            head = probe.read(4096)
        stream = open(path, encoding="utf-8", errors="replace")  # universal newlines: CRLF logs are fine
    except OSError as exc:
        raise UsageError(f"cannot read {path}: {exc.strerror or exc}") from None
    kind = _binary_kind(head)
    if kind:
        stream.close()
        raise UsageError(f"{path} is not candump text ({kind}): `ckesc check-log {path}` reads BLF, ASC and the other "
                         "capture formats python-can reads")
    return stream, stream.close


#: the first bytes of capture formats that are not text
_MAGIC = ((b"LOGG", "a BLF file"), (b"\x1f\x8b", "gzip-compressed"), (b"MDF ", "an MF4 file"),
          (b"SQLite format 3\0", "an SQLite database"))


def _binary_kind(head: bytes) -> str | None:
    """What a file that is not candump text is, from its first bytes (None: text, perhaps with a damaged
    line, which decode reports as that line's error)."""
    for magic, kind in _MAGIC:
        if head.startswith(magic):
            return kind
    text = sum(32 <= b < 127 or b in (9, 10, 13) for b in head)
    if head and (len(head) - text) * 10 > 3 * len(head):  # candump lines are printable ASCII; damage is a few bytes
        return "a binary file"
    return None


def _run_decode(args: argparse.Namespace) -> int:
    stream, release = _open_input(args.file)
    decoder = Decoder(nibble_order=args.nibble_order)
    failed = 0
    write = sys.stdout.write
    dumps = json.JSONEncoder().encode
    try:
        for record in decode_lines(stream, decoder):  # streamed: one line in memory at a time
            if "error" in record:
                failed += 1
            write(dumps(record) + "\n")
    finally:
        release()
    return ExitStatus.FAILED if failed else ExitStatus.OK


def add_decode_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "decode",
        help="decode candump lines into JSON, one object per line",
        description="Read candump lines (candump -L log, candump display form, or bare ID#DATA) from FILE or stdin "
        "and print one JSON object per frame line. A line that does not decode prints "
        '{"error": ..., "line": N, ...}. Exit 0 when every line decoded, 1 otherwise.',
    )
    p.add_argument("file", nargs="?", metavar="FILE", help="candump log; '-' or nothing: stdin")
    p.add_argument(
        "--nibble-order",
        choices=("lsb", "swapped"),
        default="lsb",
        help="RawCommand_12b nibble order (R4; 'swapped' is the one alternative a DUT profile may select)",
    )
    p.set_defaults(handler=_run_decode)
