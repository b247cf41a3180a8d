"""The run's record, typed: what several of the plugin's modules read and write (the results, the run's info,
the lane, profile and node id, why the run stopped, the DUT's frames per test), one :class:`RunState` per
pytest session in ``config.stash``. What only one module needs (the preflight's done flag, the shared cold
boots, the bus-rule watchers, the trace writer, the silent-test count) stays in that module's own stash key.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

from ..bench.lanes import Lane
from ..bench.profile import DutProfile
from ..bench.station import Station
from ..reporting import report
from ..reporting.exits import ExitStatus
from ..reporting.results import Result


class Shield:
    """A stretch that Ctrl-C / SIGTERM must not cut in the middle (writing a test's trace file out: a
    KeyboardInterrupt inside python-can's BLF writer leaves the file a bare header and the test's evidence lost).
    A context manager, re-entrant and reused for every frame written: the session's signal guard sets ``held``
    instead of raising while ``depth`` is non-zero, and the interrupt is raised here once the stretch ends."""

    def __init__(self) -> None:
        self.depth = 0
        self.held = False

    def __enter__(self) -> None:
        self.depth += 1

    def __exit__(self, *exc: object) -> None:
        self.depth -= 1
        if not self.depth and self.held:
            self.held = False
            raise KeyboardInterrupt


@dataclass
class RunState:
    results: dict[str, Result] = field(default_factory=dict)
    conformance: bool = False  # the session collected conformance tests (else the plugin stays inert)
    #: the bench the run's options build (the preflight builds it; closed at the session's end)
    station: Station | None = None
    lane: Lane | None = None
    profile: DutProfile | None = None
    node_id: int | None = None
    #: every frame the DUT sent in the run (4.1 checks), one list per test: frames between two tests
    #: (restoring settings, other fixtures) are in none, so only frames of one list are known adjacent
    dut_segments: list[list] = field(default_factory=list)
    started: float = field(default_factory=time.time)
    info: dict[str, Any] = field(default_factory=dict)
    report_dir: Path | None = None  # reports/<run>/, made at the first test that writes into it
    #: the run's tests as collected (after -k / -m deselection), and what deselection left out
    selected: list[pytest.Item] = field(default_factory=list)
    deselected: list[str] = field(default_factory=list)
    #: why the run stopped early: "aborted: ..." (the DUT did not answer, the bench went away) or
    #: "interrupted" (Ctrl-C, SIGTERM); None while it runs or when it ran to its end
    stopped: str | None = None
    #: the tests whose every phase reported (their teardown included): a result of a test not among them was cut
    #: by the run's end (an interrupt, an abort) and is no verdict (:func:`~.finish.cut_short`)
    finished: set[str] = field(default_factory=set)
    #: the run's exit status, decided once at the session's end from its results (:func:`~ckesc.reporting.exits.of_run`,
    #: ``ckesc run`` returns it); None before, or for a session that ran no conformance test
    exit_status: ExitStatus | None = None
    #: held while a trace file is written out: the first Ctrl-C / SIGTERM waits for it to end
    shield: Shield = field(default_factory=Shield)


_STATE = pytest.StashKey[RunState]()


def state(config: pytest.Config) -> RunState:
    """This session's :class:`RunState` (made on first use)."""
    return config.stash.setdefault(_STATE, RunState())


def report_dir(config: pytest.Config) -> Path | None:
    """This run's report directory (made on first use), or None without --ckesc-reports."""
    st = state(config)
    base = config.getoption("ckesc_reports")
    if st.report_dir is None and base:
        st.report_dir = report.run_dir(Path(base), st.started)
    return st.report_dir
