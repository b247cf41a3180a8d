"""The hooks that trace each conformance test's frames into the run's ``traces/`` (the files are written by
:mod:`.trace_files`): one writer per run, its listener on every lane the plugin opens, and a trace spanning each
test's setup, call and teardown."""

from __future__ import annotations

import pytest

from ..bench.lanes import Lane
from .collection import is_conformance
from .safety import EXIT_READ_S, zero_throttle_now
from .state import report_dir, state
from .trace_files import TestTraces

_WRITER = pytest.StashKey[TestTraces]()
#: trace files a test made before its own protocol (its write before a shared cold boot), by lane
EARLIER = pytest.StashKey[dict]()


def writer(config: pytest.Config) -> TestTraces | None:
    """The run's trace writer, once the first conformance test has opened it (None without traces)."""
    return config.stash.get(_WRITER, None)


def _open(config: pytest.Config) -> TestTraces | None:
    if _WRITER not in config.stash and config.getoption("ckesc_trace_format") != "none" and (out := report_dir(config)):
        config.stash[_WRITER] = TestTraces(out / "traces", config.getoption("ckesc_trace_format"),
                                           shield=state(config).shield)
    return writer(config)


def trace_lane(config: pytest.Config, lane: Lane, name: str) -> None:
    """Every frame ``lane`` reads into the current test's trace file for lane ``name`` ("" for the DUT's)."""
    traces = writer(config)
    if traces is not None:
        lane.listeners.append(traces.listener(name))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    """A conformance test's trace spans its setup, call and teardown; it is closed on every way out
    (failure, timeout, Ctrl-C)."""
    traces = _open(item.config) if is_conformance(item) else None
    if traces is None:
        return (yield)
    traces.begin(item.nodeid)
    try:
        return (yield)
    finally:
        if (state(item.config).stopped or "").startswith("interrupted"):
            # Ctrl-C / SIGTERM cut this test short, and pytest tears its fixtures down only at the session's end,
            # after this trace closes: zero throttle now, read into this trace, so that it ends on the zero
            zero_throttle_now(item.config, read_s=EXIT_READ_S)
        with state(item.config).shield:  # a Ctrl-C now is raised once the files are whole and the result names them
            paths = traces.end_relative()
            res = state(item.config).results.get(item.nodeid)
            if res is not None:
                res.traces = dict(paths)
                res.traces.update(item.stash.get(EARLIER, {}))

