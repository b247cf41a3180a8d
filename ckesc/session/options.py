"""The run's options, written once: :data:`OPTIONS` is the table from which pytest's options (the plugin's
``pytest_addoption``), ``ckesc run``'s arguments (``ckesc/cli/run.py``), the pytest command line ``ckesc run``
makes of them (:func:`command_line`, ``ckesc/run.py``) and the options a rig file sets per bench
(:data:`BENCH_OPTIONS`, ``ckesc/rigs/rig.py``) are made.

One row per option: its dest (pytest's ``config.getoption`` name, and ``ckesc run``'s ``args`` attribute),
its flags on each side (pytest's, ``ckesc run``'s, either absent where that side has no such option), how
argparse reads it (type, choices, action, default, metavar), its help (the same text on both sides), the
``ckesc run --help`` group it is listed under, and the rig file key that sets it per bench, if one does.
A new option is one row here; its use is where the option is read.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

from ..bench.arguments import percentage
from ..bench.station import BENCH_ROWS, DUT, SAME, Option
from ..reporting.compare import DEFAULT_THRESHOLD
from .trace_files import TRACE_FORMATS

#: ``ckesc run --help``'s groups, in its order (pytest's ``--help`` lists every option under one "ckesc" group)
RIG, OUTPUT, GATE = ("several benches at once (pytest-xdist: pip install 'ckesc-conformance[rig]')", "output",
                     "release gate (docs/compare.md)")
PYTEST_GROUP = ("ckesc", "CKESC conformance: device under test")
__all__ = ["DUT", "GATE", "OUTPUT", "RIG", "SAME", "Option"]  # DUT, SAME and Option: the bench's (ckesc/bench/station.py)


def _absolute(text: str) -> str:
    return str(Path(text).expanduser().resolve())


OPTIONS: tuple[Option, ...] = (
    Option("rig", group=RIG, metavar="FILE", pytest=None,
           help="a rig file (fixtures/rigs/*.toml): run on every bench of it at once, one pytest-xdist worker per bench; "
                "each bench's report in <reports>/<timestamp>/<bench>/, and batch.html, batch.json and a merged junit.xml "
                "beside them. The options below are then set per bench by the rig"),
    Option("benches", group=RIG, metavar="A,B", pytest=None, help="--rig: only these benches (default: every bench of the rig)"),
    *BENCH_ROWS,  # the device under test, its lane, bus and power: ckesc/bench/station.py, BenchOptions' fields
    Option("ckesc_order", choices=("overlap", "collection"), default="overlap", run=("--order",),
           help="overlap (default): tests that neither power-cycle nor reconfigure the DUT run while a 120 s Set ID / Set "
                "Baud window elapses, and each window test runs at its moment, persistence tests share power cycles; "
                "collection: every test in collection order, each with its own waits and cycles (verdicts are the same)"),
    Option("ckesc_reports", group=OUTPUT, metavar="DIR", run=("--reports",), run_default="reports",
           help="write JUnit, JSON, text and HTML reports under DIR/<timestamp>/, DIR/latest pointing at the newest "
                "(ckesc run: default reports/)"),
    Option("ckesc_summary", group=OUTPUT, action="store_true", default=False, run=None,
           help="print the per-section summary at the end (ckesc run sets it)"),
    Option("ckesc_no_html", group=OUTPUT, action="store_true", default=False, run=None,
           help="with --ckesc-reports: no report.html (machine readers only, e.g. ckesc selftest's runs)"),
    Option("ckesc_strict", group=OUTPUT, action="store_true", default=False, run=("--strict",),
           help="INCONCLUSIVE results fail the run too"),
    Option("ckesc_trace_format", group=OUTPUT, choices=TRACE_FORMATS, default="blf", run=("--trace-format",),
           help="each test's CAN traffic in <run>/traces/, written by python-can: blf (default; Vector BLF), asc (Vector "
                "ASCII), log (candump -L, `ckesc decode` reads it), none"),
    Option("quiet", group=OUTPUT, action="store_true", default=False, pytest=None, run=("-q", "--quiet"),
           help="no per-test progress lines"),
    Option("verbose", group=OUTPUT, action="store_true", default=False, pytest=None, run=("-v", "--verbose"),
           help="each failing test's detail on the console too (pytest's traceback and its short summary); without it "
                "the console ends with the counts and the failures by cause, each test's detail in the reports"),
    Option("ckesc_progress", group=OUTPUT, choices=("on", "off"), default="on", run=("--progress",),
           help="a line per section with the protocol time planned, elapsed and an estimate of what is left (on a "
                "terminal also after pytest's counter); off: none"),
    Option("ckesc_baseline", group=GATE, type=_absolute, metavar="DIR", run=("--baseline",),
           help="end with the comparison against this earlier run of the bench (its report directory or results.json, "
                "as `ckesc compare` reads it) over the tests both ran, and exit 1 on a regression: a requirement or test "
                "that passed and now does not, a timing margin that shrank beyond --baseline-threshold; the reasons lead "
                "summary.txt and the console's end. A baseline that is not a run, or shares no test with the "
                "selection, is exit 2 before any test"),
    Option("ckesc_baseline_threshold", group=GATE, type=percentage, default=DEFAULT_THRESHOLD * 100, metavar="PCT",
           run=("--baseline-threshold",),
           help="--baseline: a timing margin regressed when it fell by more than PCT %% of the baseline's (and by more "
                f"than the runs' stated timing error); default {DEFAULT_THRESHOLD * 100:g}, as ckesc compare's"),
    Option("ckesc_durations", group=OUTPUT, type=_absolute, metavar="RESULTS_JSON", run=("--time-from",),
           help="time left: expect each test to take the lane time it took in this earlier run of the bench (its "
                "results.json; default: the suite's own table of a faultless simulated run, conformance/durations.json)"),
)

BY_DEST: dict[str, Option] = {o.dest: o for o in OPTIONS}
#: the options a rig file sets per bench, with their defaults (given on the command line with --rig: an error)
BENCH_OPTIONS: dict[str, Any] = {o.dest: o.default for o in OPTIONS if o.rig is not None}


def add_pytest_options(parser) -> None:
    """Every option with a pytest flag, as ``pytest_addoption`` adds them (``parser``: a ``pytest.Parser``)."""
    group = parser.getgroup(*PYTEST_GROUP)
    for o in OPTIONS:
        if o.pytest_flag:
            group.addoption(o.pytest_flag, **o.arguments())


def bench_options() -> tuple[Option, ...]:
    """The options that say which bench the run drives (the device under test, its lane, bus and power): what
    ``ckesc run``, ``ckesc explore`` and ``ckesc profile`` share, the fields of :class:`~ckesc.bench.station.BenchOptions`."""
    return BENCH_ROWS


def run_options() -> Iterable[Option]:
    """``ckesc run``'s options, in ``--help``'s order."""
    return (o for o in OPTIONS if o.run_flags)


def command_line(values: Mapping[str, Any]) -> list[str]:
    """The pytest options for ``values`` (dest -> value, in their order; options without a pytest flag and unset
    values, None, "", [] or False, left out): ``--dut bus --can-config a=1 --can-config b=2 --allow-motor-spin``."""
    out: list[str] = []
    for dest, value in values.items():
        o = BY_DEST[dest]
        if o.pytest_flag is None or value is None or value is False or value == "" or value == []:
            continue
        if o.action == "store_true":
            out.append(o.pytest_flag)
        elif o.action == "append":
            for v in value:
                out += [o.pytest_flag, str(v)]
        else:
            out += [o.pytest_flag, str(value)]  # (a seed 0 is a value)
    return out
