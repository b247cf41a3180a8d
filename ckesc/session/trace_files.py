"""The trace files: per-test CAN traces, written by python-can's own log writers (the hooks that decide which
test and lanes a trace spans: :mod:`.trace_hooks`).

The plugin puts a :meth:`TestTraces.listener` on every lane it opens (``lane.listeners``).
Between :meth:`TestTraces.begin` and :meth:`TestTraces.end` (a test's setup, call and teardown)
every frame a lane reads goes to that test's file for that lane in ``traces/``: both directions
(the host's frames as their bus echo, ``is_rx`` False), with the lane's timestamps, frames that do
not decode included. A file is created at its first frame, so a test skipped before touching the
bus leaves none; frames a shared fixture read are in the trace of the test whose setup ran it.

Formats are python-can's: ``blf`` (Vector BLF, compressed; CANalyzer, CANoe, asammdf and python-can
read it), ``asc`` (Vector ASCII), ``log`` (candump -L, which ``ckesc decode`` reads).
"""

from __future__ import annotations

import hashlib
import re
from contextlib import AbstractContextManager, nullcontext
from pathlib import Path

import can

#: python-can's writer for each trace format (named, not looked up by ``can.Logger``: its plugin scan
#: costs ~5 ms per file, a second and a half over a run)
WRITERS: dict[str, type[can.io.generic.MessageWriter]] = {"blf": can.BLFWriter, "asc": can.ASCWriter,
                                                          "log": can.CanutilsLogWriter}
#: --ckesc-trace-format choices ("none": no traces)
TRACE_FORMATS = (*WRITERS, "none")

_UNSAFE = re.compile(r"[^A-Za-z0-9._=-]+")
_MAX_STEM = 150  # well inside any file system's 255-byte name limit, with room for a suffix


def trace_name(nodeid: str, fmt: str) -> str:
    """A file name for a test's trace: the node id with every unsafe run of characters replaced by
    ``_`` (``conformance/`` dropped); long names keep their start and get a hash of the whole id."""
    stem = _UNSAFE.sub("_", nodeid.removeprefix("conformance/").replace(".py::", "__")).strip("_.") or "test"
    if len(stem) > _MAX_STEM:
        stem = stem[: _MAX_STEM - 9] + "-" + hashlib.sha1(nodeid.encode()).hexdigest()[:8]
    return f"{stem}.{fmt}"


#: the default shield: none (a trace writer outside a pytest session)
_UNSHIELDED = nullcontext()


class TestTraces:
    """One trace file per test and lane under ``directory`` (see the module docstring).

    Each lane gets its own listener, :meth:`listener`, and its own file: a lane's clock is its own
    (a private simulated bench starts at 0), so two lanes' frames in one file would run backwards."""

    __test__ = False  # not a pytest test class, whatever its name

    def __init__(self, directory: Path, fmt: str = "blf", shield: AbstractContextManager = _UNSHIELDED) -> None:
        """``shield``: a reusable context manager each write to a file runs inside, so that a Ctrl-C is not raised
        into python-can's writer half-way through a block (the session's :class:`.state.Shield`)."""
        if fmt not in WRITERS:
            raise ValueError(f"trace format must be one of {', '.join(WRITERS)}, not {fmt!r}")
        self.directory = Path(directory)
        self.fmt = fmt
        self._stem: str | None = None
        self._writers: dict[str, tuple[Path, can.io.generic.MessageWriter]] = {}
        self._stems: set[str] = set()
        self._shield = shield

    def listener(self, lane: str = "") -> can.Listener:
        """The listener for one lane (``lane.listeners``); ``lane`` names its file:
        ``<test>.blf`` for the DUT's lane (""), ``<test>.<lane>.blf`` for another."""
        return _LaneTrace(self, lane)

    def begin(self, nodeid: str) -> None:
        """Start the traces of test ``nodeid``."""
        self.end()
        stem = trace_name(nodeid, self.fmt)[: -len(self.fmt) - 1]
        if stem in self._stems:  # two ids that read the same once sanitized
            stem = f"{stem}-{hashlib.sha1(nodeid.encode()).hexdigest()[:8]}"
        self._stems.add(stem)
        self._stem = stem

    def write(self, lane: str, msg: can.Message) -> None:
        if self._stem is None:
            return  # between tests: nobody's frame
        entry = self._writers.get(lane)
        if entry is None:
            self.directory.mkdir(parents=True, exist_ok=True)
            path = self.directory / ".".join(filter(None, (self._stem, lane, self.fmt)))
            entry = self._writers[lane] = (path, WRITERS[self.fmt](path))
        with self._shield:
            entry[1].on_message_received(msg)

    def end(self) -> dict[str, Path]:
        """Close the current test's files; returns them by lane (a lane that heard no frame has none)."""
        writers, self._writers, self._stem = self._writers, {}, None
        for _, writer in writers.values():
            writer.stop()
        return {lane: path for lane, (path, _) in writers.items()}

    def end_relative(self) -> dict[str, str]:
        """:meth:`end`, each file named relative to the run's report directory (as the reports name it)."""
        return {lane: path.relative_to(self.directory.parent).as_posix() for lane, path in self.end().items()}


class _LaneTrace(can.Listener):
    def __init__(self, traces: TestTraces, lane: str) -> None:
        self.traces, self.lane = traces, lane

    def on_message_received(self, msg: can.Message) -> None:
        self.traces.write(self.lane, msg)

    def stop(self) -> None:
        pass  # the files belong to the test, closed by TestTraces.end()
