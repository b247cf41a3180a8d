"""A soak's frames on disk within a budget (``--trace-budget``): a rolling candump log of every frame heard, in
:data:`ROLL_FILES` files (``trace-000001.log``, ...) of which the oldest is deleted as a new one starts, and each
finding's frames (:class:`~.watch.SoakFinding`: the ring before it and the frames after it) in a file of its own
(``finding-001.log``), never deleted. Room for :data:`~.watch.MAX_FINDINGS` finding files is set aside from the
budget first; the rest is the rolling log's, so the files together never exceed the budget.

The lines are candump's log format (``candump -L``; python-can's ``CanutilsLogReader`` reads them): ``(time)
interface id#data``, the time in seconds into the run. Nothing is kept in memory but the open file.
"""

from __future__ import annotations

import re
from collections import deque
from pathlib import Path
from typing import Any

from .watch import AFTER_FRAMES, MAX_FINDINGS, RING_FRAMES, SoakFinding

#: the rolling log's files: the budget's rolling part split among them, the oldest deleted as the next one starts
ROLL_FILES = 4
#: the interface name candump's lines carry
INTERFACE = "soak"
#: one line at most (a day's time into the run, an extended id, 8 data bytes): sizes the finding files' reserve
LINE_MAX = len(f"({86400 * 7:.6f}) {INTERFACE} {0:08X}#{'00' * 8}\n")
#: what one finding's file may take: the frames before it and after it
FINDING_BYTES = (RING_FRAMES + AFTER_FRAMES) * LINE_MAX
#: the smallest rolling file worth rolling
MIN_FILE_BYTES = 4096
#: the default budget, and the smallest one that holds the finding files' reserve and the rolling files
DEFAULT_BUDGET = 200 * 1000 * 1000
MIN_BUDGET = MAX_FINDINGS * FINDING_BYTES + ROLL_FILES * MIN_FILE_BYTES

_UNITS = {"": 1, "b": 1, "kb": 10**3, "mb": 10**6, "gb": 10**9, "kib": 2**10, "mib": 2**20, "gib": 2**30}


def parse_size(text: str) -> int:
    """``200MB``, ``1.5GB``, ``512KiB``, ``0`` -> bytes (decimal units, or binary with ``i``)."""
    m = re.fullmatch(r"\s*(\d+(?:\.\d+)?)\s*([a-zA-Z]*)\s*", text)
    if not m or m.group(2).lower() not in _UNITS:
        raise ValueError(f"a size like 200MB, 1GB or 500kB, not {text!r}")
    return int(float(m.group(1)) * _UNITS[m.group(2).lower()])


def candump_line(t: float, can_id: int, data: bytes) -> str:
    return f"({t:.6f}) {INTERFACE} {can_id:08X}#{data.hex().upper()}\n"


#: lines held before they are written (one write of many lines costs less than many writes: a soak writes every frame)
BATCH_LINES = 256
#: the ids' ``) soak 0CXXXXXX#`` and the payloads' hex kept, as :data:`~.watch.MAX_IDS` bounds the watches' own
#: (a bus of few ids and few payloads, hours long: the same strings again)
MAX_CACHED = 4096


class Trace:
    """The run's trace in directory ``where`` within ``budget`` bytes (at least :data:`MIN_BUDGET`), times into the
    run from lane time ``t0``: :meth:`frame` each frame heard, :meth:`finding` each finding once its frames after it
    are read, :meth:`close` at the end; :meth:`to_json` names the files."""

    def __init__(self, where: Path, budget: int, t0: float) -> None:
        if budget < MIN_BUDGET:
            raise ValueError(f"--trace-budget {budget} bytes: at least {MIN_BUDGET} (room for {MAX_FINDINGS} findings' "
                             f"frames and {ROLL_FILES} rolling files), or 0 for no trace")
        self.where, self.budget, self.t0 = where, budget, t0
        self.file_limit = (budget - MAX_FINDINGS * FINDING_BYTES) // ROLL_FILES
        self.files: deque[Path] = deque()
        self.index = 0
        self.rolled_away = 0  # files deleted
        self.frames = 0
        self.finding_files: list[str] = []
        self._fh: Any = None
        self._size = 0
        self._lines: list[str] = []
        self._ids: dict[int, str] = {}
        self._hex: dict[bytes, str] = {}
        self._roll()

    def _roll(self) -> None:
        if self._fh is not None:
            self._flush()
            self._fh.close()
        if len(self.files) == ROLL_FILES:
            self.files.popleft().unlink(missing_ok=True)
            self.rolled_away += 1
        self.index += 1
        path = self.where / f"trace-{self.index:06d}.log"
        self.files.append(path)
        self._fh = open(path, "w", encoding="ascii")  # noqa: SIM115 - kept open across calls, closed by _roll/close
        self._size = 0

    def frame(self, t: float, can_id: int, data: bytes) -> None:
        # candump_line's, with the id's and the payload's text remembered (the hot path of a soak: every frame)
        ids = self._ids.get(can_id)
        if ids is None:
            if len(self._ids) >= MAX_CACHED:
                self._ids.clear()
            ids = self._ids[can_id] = f") {INTERFACE} {can_id:08X}#"
        key = bytes(data)
        text = self._hex.get(key)
        if text is None:
            if len(self._hex) >= MAX_CACHED:
                self._hex.clear()
            text = self._hex[key] = key.hex().upper() + "\n"
        line = f"({t - self.t0:.6f}{ids}{text}"
        if self._size + len(line) > self.file_limit:
            self._roll()
        lines = self._lines
        lines.append(line)
        if len(lines) >= BATCH_LINES:
            self._flush()
        self._size += len(line)
        self.frames += 1

    def _flush(self) -> None:
        if self._lines:
            self._fh.write("".join(self._lines))
            self._lines.clear()

    def finding(self, finding: SoakFinding) -> str:
        """``finding``'s frames (before and after it) in a file of its own; returns its name (also set on the
        finding: results.json names it)."""
        name = f"finding-{len(self.finding_files) + 1:03d}.log"
        lines = []
        for line in (*finding.before, *finding.after):
            t, frame = line.split()
            can_id, _, data = frame.partition("#")
            lines.append(candump_line(float(t), int(can_id, 16), bytes.fromhex(data)))
        (self.where / name).write_text("".join(lines), encoding="ascii")
        self.finding_files.append(name)
        finding.file = name
        return name

    def close(self) -> None:
        if self._fh is not None:
            self._flush()
            self._fh.close()
            self._fh = None

    def bytes_on_disk(self) -> int:
        return sum(p.stat().st_size for p in (*self.files, *(self.where / n for n in self.finding_files)) if p.exists())

    def to_json(self) -> dict[str, Any]:
        return {"budget_bytes": self.budget, "format": "candump -L, times into the run", "frames": self.frames,
                "rolling": [p.name for p in self.files], "rolling_file_bytes": self.file_limit,
                "rolled_away": self.rolled_away, "findings": list(self.finding_files), "bytes": self.bytes_on_disk()}
