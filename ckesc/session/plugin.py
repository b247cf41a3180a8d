"""The pytest plugin (entry point ``pytest11``): the run's options and markers, and the plugin's modules, one per
concern, registered for the session.

It stays inert in a pytest run that collects no conformance test (the project's own tests): the
options exist, but nothing is opened and no report is written.

The modules, each a plugin of its own (its hooks and fixtures) holding what only it needs in its own stash key,
and reading and writing the run's typed record (:mod:`.state`):

    collection    which tests are the suite's, the requirement check, the preflight
    order         the run order: waits that overlap (schedule.py), pytest's loop or a batch worker's
    cold_boots    tests sharing one proven power cycle between their writes and their reads
    fixtures      ckesc_lane, dut, multi_dut, record, ckesc_run; zero throttle on every way out, the signal guard
    trace_hooks   each test's CAN trace: its span and the lanes traced (trace_files.py writes the files)
    bus_rules     the rules that hold at all times, live over every frame
    verdicts      each test's phase reports -> its one Result, and the console's count of it
    finish        the session's end: complete or why not, exit status, the reports written
    baseline      the release gate (--baseline): the baseline checked before any test, judged at the end

How they load, on purpose: this module registers them in ``pytest_configure`` with
``config.pluginmanager.register(module, name)``, as pytest-xdist registers its session object. Not through
``pytest_plugins``: pytest marks every module named there for assertion rewriting and warns for each one already
imported, and these are (they import each other, and ``ckesc run`` imports them before pytest starts). Modules
rather than objects, because pytest reads fixtures and hooks from a module as they are written, and what is one
run's lives in ``config.stash`` either way. ``-p no:ckesc`` leaves all of them out.
"""

from __future__ import annotations

import pytest

from . import baseline, bus_rules, cold_boots, collection, finish, fixtures, options, order, trace_hooks, verdicts
from .progress import ProgressReporter
from .state import state

#: the plugin's modules, registered in this order (pluggy calls the later registered first, among equals)
MODULES = (collection, order, cold_boots, fixtures, trace_hooks, bus_rules, verdicts, finish, baseline)


def pytest_addoption(parser: pytest.Parser) -> None:
    options.add_pytest_options(parser)


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "requirement(*ids): the requirement ids (requirements.toml) a test checks")
    config.addinivalue_line("markers", "power_cycle: the test cycles the DUT's power")
    config.addinivalue_line("markers", "spins_motor: the test commands non-zero throttle")
    config.addinivalue_line("markers", "last: run after every other conformance test (run-wide checks)")
    config.addinivalue_line("markers", "may_power_cycle: on some benches the test power-cycles or sends Set ID (e.g. "
                            "answer slots on a coarse bench): never run while a Set ID / Set Baud window elapses")
    config.addinivalue_line("markers", "cold_boot(write, touches=setting): needs a cold boot between write(dut, "
                            "**params) and its read (cold_boot fixture); the run order may share one power cycle")
    config.addinivalue_line("markers", "window(kind): acts at a moment of the 120 s Set ID / Set Baud window "
                            "(kind 'inside' or 'after'; the run order overlaps the window with other tests)")
    st = state(config)
    _print_ids_as_reported(config)
    for module in MODULES:
        if not config.pluginmanager.is_registered(module):
            config.pluginmanager.register(module, module.__name__)
    config.pluginmanager.register(ProgressReporter(config, lambda: st.lane.peek_now() if st.lane is not None else None,
                                                   collection.section_title, collection.is_conformance), "ckesc-progress")


def _print_ids_as_reported(config: pytest.Config) -> None:
    """The console names a conformance test by its id as the reports write it (``conformance/test_...``), from
    any directory and any install: pytest would print it relative to the directory it was started in
    (``../../site-packages/conformance/...`` from elsewhere, or against an editable install)."""
    relative = config.cwd_relative_nodeid

    def as_reported(nodeid):
        return nodeid if str(nodeid).startswith("conformance/") else relative(nodeid)  # a str, or pytest 9.2+'s NodeId

    config.cwd_relative_nodeid = as_reported  # type: ignore[method-assign]
