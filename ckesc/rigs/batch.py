"""Several benches in one pytest session through pytest-xdist (``ckesc run --rig``): one worker per bench,
each running every selected test against its own bench, with its own plugin state and its own report.

How: ``-n N --dist each`` (xdist sends every test to every worker), ``-p ckesc.rigs.batch`` (this module,
loaded in every worker too), and :class:`Controller` in the controlling process, which

* gives each worker its bench when xdist sets it up (``pytest_configure_node``: the bench's plugin options
  and report directory go in ``workerinput``; the worker sets its ``config.option`` from them before the
  session starts, so each worker's session is a one-bench run as ``ckesc run`` would make it);
* schedules with :class:`BenchScheduling`, xdist's own ``each`` scheduling, except that a bench whose worker
  ends early (its DUT did not answer: abort, exit 3; its worker died) is not a "crashed item" of the
  batch and does not hold up the others;
* prints one line per bench finished (``pytest_testnodedown``);
* on Ctrl-C / SIGTERM, sends SIGINT once to each worker (each worker is in a process group of its own, so
  the terminal's Ctrl-C reaches it only this way, exactly once) and keeps waiting for them: each stops
  with zero throttle through the plugin's own signal guard, tears its fixtures down and writes its report.

Why ``--dist each`` with a bench per worker, and not the load-sharing modes or N separate ``ckesc run``
processes: the ckesc plugin's whole state (lane, DUT, preflight, abort, signal guard, report) lives in one
pytest session; a worker that runs every test keeps that state, and so the bench's report, whole and exactly
as a one-bench run writes it, while xdist does what would otherwise be written here (starting and watching
the processes, the event stream from each, a worker that dies).

A worker's set-up mistake found by its preflight (its bus does not open, ...), or anything else that breaks
its set-up, does not end the worker as a crash would: it is kept as the bench's ``setup_error``, the worker
runs none of its tests, and the batch reports the bench ABSENT. (A worker process that dies before every
worker has collected its tests would still end the batch early: xdist stops scheduling once a worker is
lost and none may be restarted; a worker that dies later is reported BROKEN and the others go on.)
"""

from __future__ import annotations

import logging
import os
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
from xdist.scheduler import EachScheduling

from ..session import collection, order
from ..session.progress import BatchProgress
from ..session.state import state

WORKER_KEY = "ckesc_bench"
_SETUP_ERROR = pytest.StashKey[str]()


# ----------------------------------------------------------------------------------------- worker
def _bench_of(config: pytest.Config) -> dict[str, Any] | None:
    return getattr(config, "workerinput", {}).get(WORKER_KEY)


@pytest.hookimpl(trylast=True)
def pytest_configure(config: pytest.Config) -> None:
    bench = _bench_of(config)
    if bench is None:
        return
    try:
        os.setpgid(0, 0)  # the terminal's Ctrl-C goes to the controller, which passes it on once
    except OSError:
        pass
    unknown = [dest for dest in bench["options"] if not hasattr(config.option, dest)]
    if unknown:
        config.stash[_SETUP_ERROR] = (f"this ckesc has no option --{unknown[0].replace('_', '-')} (the rig asks for it; "
                                      "labgrid power and places need the labgrid support: pip install -e '.[rig]')")
        return
    for dest, value in bench["options"].items():
        setattr(config.option, dest, value)
    # pytest's logging capture is not on yet: log records of the preflight (python-can's socketcand client warns
    # ten times a millisecond while it retries a refused connection) go nowhere, as in a one-bench run's preflight
    quiet = logging.NullHandler()
    logging.getLogger().addHandler(quiet)
    try:
        out = Path(bench["report_dir"])
        out.mkdir(parents=True, exist_ok=True)
        st = state(config)
        st.report_dir = out  # reports/<batch>/<bench>/, not a new timestamped directory
        st.info["run_id"] = f"{out.parent.name}/{bench['name']}"
        collection.preflight(config)  # here, so that a bench's mistake is its own and not a crash
    except pytest.UsageError as exc:
        config.stash[_SETUP_ERROR] = str(exc)
    except Exception as exc:  # noqa: BLE001 - whatever breaks one bench's set-up must not end its worker: xdist
        # would then stop the benches that have not collected their tests yet
        config.stash[_SETUP_ERROR] = f"the bench's set-up failed: {type(exc).__name__}: {exc}"
    finally:
        logging.getLogger().removeHandler(quiet)


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if _bench_of(config) is not None and _SETUP_ERROR not in config.stash:
        try:  # the bench proven (its bus's ESCs, its power switch) as a one-bench run proves it: its mistake is its own
            collection.bench_proof(config, [it for it in items if collection.is_conformance(it)])
        except pytest.UsageError as exc:
            config.stash[_SETUP_ERROR] = str(exc)
        except Exception as exc:  # noqa: BLE001 - as the preflight's: the worker must not die of it
            config.stash[_SETUP_ERROR] = f"the bench's set-up failed: {type(exc).__name__}: {exc}"
    if _bench_of(config) is not None and _SETUP_ERROR in config.stash:
        items[:] = []  # nothing of this bench can run: its worker ends at once, the others go on


# The bench's run order (issue #21): the same plan, shared windows and cold boots as the bench alone (session/order.py's
# PlanRunner), run through xdist's own worker loop. With ``--dist each`` the worker is told to run every test, and
# it takes each test from ``session.items`` by position when it gets to it (the test after it too, as pytest's
# ``nextitem``). So the plan's choice is put at the next position between two tests, and what pytest is to be told
# comes after it at the position after that: the worker runs the plan's order, every test once, each report sent
# for the test at its own position. Nothing of xdist is replaced or reached into.
_RUNNER = pytest.StashKey[order.PlanRunner]()


@pytest.hookimpl(tryfirst=True)
def pytest_runtestloop(session: pytest.Session) -> None:
    """Before xdist's worker loop: the plan's first test (and its hint) at the first positions."""
    config = session.config
    if _bench_of(config) is None or _SETUP_ERROR in config.stash or not order.overlaps(session):
        return None
    runner = order.overlap_plan(session)
    first = runner.first() if runner is not None else None
    if first is None:
        return None
    config.stash[_RUNNER] = runner
    _place(session.items, 0, first, runner.before(first))
    return None  # xdist's loop runs the tests


@pytest.hookimpl(hookwrapper=True, tryfirst=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None):
    """After each test (outside its own timeout): the plan chooses the next one, which goes to the next position."""
    yield
    runner = item.config.stash.get(_RUNNER, None)
    if runner is None:
        return
    items = item.session.items
    nxt = runner.after(item)
    if nxt is not None:
        _place(items, items.index(item) + 1, nxt, runner.before(nxt))


def _place(items: list[pytest.Item], at: int, item: pytest.Item, then: pytest.Item | None) -> None:
    """``item`` to position ``at`` and ``then`` after it (both not run yet, so both at or after ``at``)."""
    for pos, it in ((at, item), (at + 1, then)):
        if it is None or pos >= len(items):
            continue
        j = items.index(it, at)
        items[pos], items[j] = items[j], items[pos]


@pytest.hookimpl(trylast=True)
def pytest_sessionfinish(session: pytest.Session) -> None:
    config = session.config
    bench = _bench_of(config)
    if bench is None:
        return
    st = state(config)
    config.workeroutput[WORKER_KEY] = {"name": bench["name"], "setup_error": config.stash.get(_SETUP_ERROR, None),
                                       "stopped": st.stopped, "exitstatus": int(session.exitstatus)}


# ----------------------------------------------------------------------------------------- controller
class BenchScheduling(EachScheduling):
    """xdist's ``each`` scheduling (every test to every worker), for benches that may end early: a worker
    that ends with tests pending (its bench aborted, or the worker died) is recorded, not reported as a
    crashed test of the batch, and one that ends before its collection does not keep the others waiting."""

    def __init__(self, config: pytest.Config, log=None) -> None:
        super().__init__(config, log)
        self.ended_early: dict[str, int] = {}  # worker id -> tests it did not get to

    def remove_node(self, node) -> str | None:
        pending = self.node2pending.pop(node, None)
        if pending:
            self.ended_early[node.gateway.id] = len(pending)
        if node not in self.node2collection and not self.collection_is_completed:
            self.numnodes -= 1  # it will never send a collection
            if self.node2collection and len(self.node2collection) >= self.numnodes:
                self.collection_is_completed = True
                self.schedule()
        return None


class Controller:
    """The controlling process's side of a batch (registered by :func:`ckesc.run.run_batch`)."""

    def __init__(self, benches: list[dict[str, Any]], *, on_finished: Callable[[str, dict[str, Any]], None]) -> None:
        #: per bench: name, options (plugin dests), report_dir
        self.benches = benches
        self.on_finished = on_finished
        self.nodes: dict[str, dict[str, Any]] = {}  # worker id -> its bench
        self.pids: dict[str, int] = {}
        self.finished: dict[str, dict[str, Any]] = {}  # bench name -> what its worker said (or how it died)
        self.started = time.time()
        self.interrupted = False
        self._previous: dict[int, Any] = {}
        self.progress = BatchProgress(lambda line: print(line, flush=True))

    # xdist hooks
    @pytest.hookimpl
    def pytest_xdist_make_scheduler(self, config: pytest.Config, log):
        return BenchScheduling(config, log)

    @pytest.hookimpl
    def pytest_configure_node(self, node) -> None:
        free = [b for b in self.benches if b["name"] not in {n["name"] for n in self.nodes.values()}]
        bench = free[0] if free else None  # a replacement for a dead worker gets no bench (none is started: 0 restarts)
        if bench is None:
            return
        self.nodes[node.gateway.id] = bench
        node.workerinput[WORKER_KEY] = bench
        try:
            # execnet asked the worker for its facts (pid among them) before this hook; xdist caches them
            self.pids[node.gateway.id] = int(node.gateway._rinfo().pid)  # noqa: SLF001
        except Exception:  # noqa: BLE001 - without it a Ctrl-C still reaches the workers through their gateway
            pass
        if self.interrupted:
            self._signal(node.gateway.id)

    @pytest.hookimpl
    def pytest_xdist_node_collection_finished(self, node, ids) -> None:
        bench = self.nodes.get(node.gateway.id)
        if bench is not None and ids:
            self.progress.collected(bench["name"], list(ids))

    @pytest.hookimpl
    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        node = getattr(report, "node", None)  # the worker that ran it (xdist's report of a worker's test)
        bench = self.nodes.get(node.gateway.id) if node is not None else None
        if bench is not None and report.when == "teardown":
            self.progress.test_ended(bench["name"], report.nodeid)

    @pytest.hookimpl
    def pytest_testnodedown(self, node, error) -> None:
        bench = self.nodes.get(node.gateway.id)
        if bench is None or bench["name"] in self.finished:
            return
        said = dict(getattr(node, "workeroutput", {}).get(WORKER_KEY) or {})
        if error is not None and not said:
            said["crash"] = f"its worker process ended: {error}"
        said["seconds"] = time.time() - self.started
        self.finished[bench["name"]] = said
        self.on_finished(bench["name"], said)

    # Ctrl-C
    def install_signals(self) -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            self._previous[sig] = signal.signal(sig, self._stop)

    def restore_signals(self) -> None:
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)

    def _stop(self, signum, frame) -> None:  # noqa: ARG002
        if self.interrupted:
            print("ckesc run: still stopping: every bench ends its test with zero throttle and writes its report",
                  file=sys.stderr, flush=True)
            return
        self.interrupted = True
        print(f"ckesc run: {signal.Signals(signum).name}: stopping every bench (zero throttle, then its report)",
              file=sys.stderr, flush=True)
        for wid in self.pids:
            self._signal(wid)

    def _signal(self, wid: str) -> None:
        bench = self.nodes.get(wid)
        if wid in self.pids and bench is not None and bench["name"] not in self.finished:
            try:
                os.kill(self.pids[wid], signal.SIGINT)
            except (ProcessLookupError, PermissionError):
                pass
