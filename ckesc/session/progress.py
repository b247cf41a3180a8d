"""Time left: a run shown as time, not only as a count of tests (issue #21).

The run's *planned protocol time* is the sum of what each selected test is expected to take on the lane's
clock: the suite's own table (``conformance/durations.json``: each test's lane seconds in a faultless
simulated run, i.e. the waits the protocol imposes), or an earlier run's ``results.json`` (``--ckesc-durations
FILE``, e.g. ``reports/latest/results.json`` of the same bench); a test in neither counts as the table's
median. As tests end, :class:`RunClock` corrects the estimate by how the run is actually going (lane time
spent over the expected time of the tests done, shrunk towards 1 while little has run): power cycles
between tests, a DUT slower than the emulator, a run order that cannot overlap its waits. Wall time left is
the lane time left at the run's own wall/lane ratio, so the same estimate serves the simulated lane (a
10 minute protocol in seconds) and real time.

The plugin object :class:`ProgressReporter` prints one line per section as the run enters it (what CI logs
keep), and on a terminal appends the time left to pytest's own progress counter, so the line pytest
updates is the one that says it. ``RunClock`` is plain: times in, text out.
"""

from __future__ import annotations

import json
import re
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import pytest

from ..protocol.requirements import Verdict, section_heading

#: the suite's own table of expected lane seconds per test id (``python -m ckesc.session.progress``)
TABLE = Path(__file__).resolve().parents[2] / "conformance" / "durations.json"
#: how many lane seconds of "expected" the correction needs before it trusts the run's own pace fully
SHRINK_S = 60.0
#: wall seconds after which a section the run comes back to is said again
REPEAT_S = 30.0


def read_table(path: str | Path | None = None) -> dict[str, float]:
    """{test id: expected lane seconds} from the suite's table, or from a ``results.json`` (its tests' ``lane_seconds``)."""
    path = Path(path) if path is not None else TABLE
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    if isinstance(doc, dict) and "results" in doc:  # a run's results.json
        return {r["nodeid"]: float(r.get("lane_seconds") or 0.0) for r in doc["results"] if r.get("outcome") != Verdict.SKIPPED}
    return {str(k): float(v) for k, v in (doc.get("lane_seconds", {}) if isinstance(doc, dict) else {}).items()}


def _clock(seconds: float) -> str:
    seconds = max(int(round(seconds)), 0)
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}" if seconds >= 3600 else f"{seconds // 60}:{seconds % 60:02d}"


@dataclass
class RunClock:
    """The estimate. ``expected``: lane seconds per test id of the run's tests (in any order)."""

    expected: dict[str, float]
    lane_started: float = 0.0
    wall_started: float = 0.0
    done_expected: float = 0.0
    lane_now: float = 0.0
    wall_now: float = 0.0
    done: set[str] = field(default_factory=set)

    @property
    def planned(self) -> float:
        return sum(self.expected.values())

    def start(self, lane: float, wall: float) -> None:
        self.lane_started, self.wall_started = lane, wall
        self.lane_now, self.wall_now = lane, wall

    def finished(self, nodeid: str, lane: float, wall: float) -> None:
        if nodeid in self.expected and nodeid not in self.done:
            self.done.add(nodeid)
            self.done_expected += self.expected[nodeid]
        self.lane_now, self.wall_now = lane, wall

    @property
    def lane_spent(self) -> float:
        return max(self.lane_now - self.lane_started, 0.0)

    @property
    def wall_spent(self) -> float:
        return max(self.wall_now - self.wall_started, 0.0)

    @property
    def pace(self) -> float:
        """Lane time the run takes per expected second, so far (1 before anything is known)."""
        return (self.lane_spent + SHRINK_S) / (self.done_expected + SHRINK_S)

    @property
    def lane_left(self) -> float:
        return max(self.planned - self.done_expected, 0.0) * self.pace

    @property
    def wall_left(self) -> float:
        """Wall seconds left: the lane time left at this run's wall/lane ratio (real time: about 1)."""
        if self.lane_spent <= 0:
            return self.lane_left
        return self.lane_left * self.wall_spent / self.lane_spent

    def line(self, where: str = "") -> str:
        head = f"[{where}] " if where else ""
        if not self.done:  # nothing has run: no pace yet, in lane or wall time
            return f"{head}protocol time planned ~{self.planned:.0f} s ({len(self.expected)} tests)"
        return (f"{head}protocol time {self.lane_spent:.0f} s of ~{self.lane_spent + self.lane_left:.0f} s, "
                f"{_clock(self.wall_spent)} elapsed, ~{_clock(self.wall_left)} left "
                f"({len(self.done)} of {len(self.expected)} tests)")

    def wall_line(self, where: str = "") -> str:
        """What a batch's controller can say of a bench: it sees tests end, not the bench's lane clock."""
        head = f"[{where}] " if where else ""
        return f"{head}{len(self.done)} of {len(self.expected)} tests, {_clock(self.wall_spent)} elapsed, ~{_clock(self.wall_left)} left"

    def suffix(self) -> str:
        return f" ~{_clock(self.wall_left)} left" if self.done else ""


def expected_for(ids: list[str], durations: str | Path | None = None) -> dict[str, float]:
    """Expected lane seconds of each of ``ids``: an earlier run's (``durations``, a results.json) first, then the
    suite's table; a test in neither counts as the table's median."""
    table = {**read_table(), **(read_table(durations) if durations else {})}
    known = [v for v in table.values() if v > 0]
    default = statistics.median(known) if known else 1.0
    return {i: table.get(i, default) for i in ids}


_SECTION_OF_ID = re.compile(r"test_s(\d+(?:_\d+)*)_|test_(attachment|robustness)_")


def section_of_id(nodeid: str) -> str:
    """``conformance/test_s4_4_22_set_freq.py::...`` -> ``4.4.22 Set/Get Freq`` (a batch's controller has ids only)."""
    m = _SECTION_OF_ID.search(str(nodeid))
    section = (m.group(1).replace("_", ".") if m.group(1) else m.group(2)) if m else ""
    return section_heading(section)


class BatchProgress:
    """Each bench's time left in a batch (``ckesc run --rig``), said by the controlling process as the bench enters a
    section: the controller hears each bench's tests end (pytest-xdist's reports), so the pace is in wall time."""

    def __init__(self, say: Callable[[str], None]) -> None:
        self.say = say
        self.clocks: dict[str, RunClock] = {}
        self.current: dict[str, str] = {}

    def collected(self, bench: str, ids: list[str]) -> None:
        now = time.monotonic()
        self.clocks[bench] = clock = RunClock(expected_for(ids))
        clock.start(now, now)

    def test_ended(self, bench: str, nodeid: str) -> None:
        clock = self.clocks.get(bench)
        if clock is None:
            return
        now = time.monotonic()
        clock.finished(str(nodeid), now, now)
        section = section_of_id(nodeid)
        if section != self.current.get(bench):
            self.current[bench] = section
            self.say(f"time: {bench}: {clock.wall_line(section)}")


class ProgressReporter:
    """The run's time as pytest reports it: registered by the ckesc plugin for conformance runs.
    ``lane_now``: the lane's clock (None before the lane is open); ``section_of``: an item's section title."""

    def __init__(self, config: pytest.Config, lane_now: Callable[[], float | None],
                 section_of: Callable[[pytest.Item], str], is_conformance: Callable[[pytest.Item], bool]) -> None:
        self.config = config
        self._lane_now = lane_now
        self._section_of = section_of
        self._is_conformance = is_conformance
        self.clock: RunClock | None = None
        self._sections: dict[str, str] = {}
        self._current = ""
        self._said: set[str] = set()
        self._last_said = 0.0
        self._mid_line = False

    def _now(self) -> tuple[float | None, float]:
        return self._lane_now(), time.monotonic()

    @pytest.hookimpl(trylast=True)
    def pytest_collection_finish(self, session: pytest.Session) -> None:
        items = [it for it in session.items if self._is_conformance(it)]
        if not items:
            return
        self.clock = RunClock(expected_for([it.nodeid for it in items], self.config.getoption("ckesc_durations")))
        self._sections = {it.nodeid: self._section_of(it) for it in items}
        tr = self.config.pluginmanager.get_plugin("terminalreporter")
        if tr is not None and getattr(tr, "isatty", False) and hasattr(tr, "_get_progress_information_message"):
            counter = tr._get_progress_information_message  # pytest's own "[n/N]": the line a terminal updates

            def with_time_left() -> str:
                text = counter()
                return text[:-1] + self.clock.suffix() + "]" if self.clock and text.endswith("]") else text

            tr._get_progress_information_message = with_time_left

    @pytest.hookimpl(tryfirst=True)  # before pytest's own line for the test starts
    def pytest_runtest_logstart(self, nodeid: str, location) -> None:
        if self.clock is None or nodeid not in self._sections:
            return
        lane, wall = self._now()
        if lane is not None and not self.clock.wall_started:
            self.clock.start(lane, wall)
        section = self._sections[nodeid]
        # a line as the run enters a section (the run order interleaves sections around the Set ID window: a
        # section seen before is said again only when nothing was said for REPEAT_S of wall time)
        if section != self._current and (section not in self._said or wall - self._last_said >= REPEAT_S):
            self._current = section
            self._said.add(section)
            self._last_said = wall
            if lane is not None:
                self.clock.lane_now, self.clock.wall_now = lane, wall
            self._say(self.clock.line(section))

    def pytest_runtest_logfinish(self, nodeid: str, location) -> None:
        if self.clock is None or nodeid not in self._sections:
            return
        lane, wall = self._now()
        if lane is None:
            return
        if not self.clock.wall_started:
            self.clock.start(lane, wall)
        self.clock.finished(nodeid, lane, wall)
        self._mid_line = self.config.get_verbosity() < 0  # -q: pytest wrote a progress letter for it

    def pytest_sessionfinish(self, session: pytest.Session) -> None:
        if self.clock is not None and self.clock.done:
            self._say(self.clock.line("end"))

    def _say(self, text: str) -> None:
        tr = self.config.pluginmanager.get_plugin("terminalreporter")
        if tr is None or self.config.getoption("ckesc_progress") == "off":
            return
        if self._mid_line:  # -q: pytest's progress letters since the last line; ours starts a line of its own
            tr.line("")
            self._mid_line = False
        tr.write_line(f"time: {text}", cyan=True)


def write_table(results: str | Path, out: str | Path = TABLE) -> int:
    """The suite's table from a faultless simulated run's results.json; the number of tests written."""
    doc = json.loads(Path(results).read_text(encoding="utf-8"))
    info = doc.get("info", {})
    if info.get("lane") != "simulated" or info.get("faults") or not info.get("complete"):
        raise SystemExit("the table is made from a complete, faultless run in the simulated lane (ckesc run)")
    seconds = {r["nodeid"]: round(float(r.get("lane_seconds") or 0.0), 3) for r in doc["results"]}
    Path(out).write_text(json.dumps({"about": "each conformance test's lane seconds in a faultless simulated run "
                                              "(ckesc/session/progress.py; remake: python -m ckesc.session.progress "
                                              "reports/latest/results.json)", "lane_seconds": seconds},
                                    indent=1, sort_keys=False) + "\n", encoding="utf-8")
    return len(seconds)


if __name__ == "__main__":
    import sys

    n = write_table(sys.argv[1] if len(sys.argv) > 1 else "reports/latest/results.json")
    print(f"{TABLE}: {n} tests")
