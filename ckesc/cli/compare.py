"""``ckesc compare``: its arguments, output files and exit code; :mod:`ckesc.reporting.compare` compares the runs."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from ..bench.arguments import percentage
from ..reporting import compare, comparing, soak_compare
from ..reporting.exits import ExitStatus
from .common import check_file


def _percent(text: str) -> float:
    return percentage(text) / 100


def _run_compare(args: argparse.Namespace) -> int:
    try:
        docs = [comparing.read_doc(path) for path in args.runs]
        soaks = [comparing.is_soak(doc) for _, doc in docs]
        if any(soaks) and not all(soaks):
            kinds = ", ".join(f"{path} a {'soak' if s else 'conformance'} run" for path, s in zip(args.runs, soaks))
            print(f"ckesc compare: error: cannot compare a soak run with a conformance run ({kinds}): give runs of "
                  "one kind", file=sys.stderr)
            return ExitStatus.USAGE
        if all(soaks):
            doc = soak_compare.compare([soak_compare.parse_soak(d, label=label, path=str(path))
                                        for path, (label, d) in zip(args.runs, docs)])
            render = soak_compare
        else:
            doc = compare.compare([compare.parse_run(d, label=label, path=str(path))
                                   for path, (label, d) in zip(args.runs, docs)], threshold=args.margin_threshold)
            render = compare
    except comparing.RunError as exc:
        print(f"ckesc compare: error: cannot read run {exc}", file=sys.stderr)
        return ExitStatus.USAGE
    try:
        if args.json:
            Path(args.json).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        if args.html:
            Path(args.html).write_text(render.page(doc), encoding="utf-8")
    except OSError as exc:
        print(f"ckesc compare: error: cannot write {exc.filename}: {exc.strerror}", file=sys.stderr)
        return ExitStatus.USAGE
    print(render.text(doc))
    return ExitStatus.FAILED if doc["regressed"] else ExitStatus.OK


def add_compare_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("compare", help="what changed between runs: regressions, fixes, tests added/removed, shrinking margins",
                       description=compare.__doc__.split("\n\n:func:")[0] + "\n\nSoak runs (ckesc soak's reports) are compared with soak runs: per "
                       "watched property its findings, the statement's bound, R9 per minute, the answer delays; a "
                       "property with findings that had none is a regression.\n\nExit 0: nothing regressed; 1: something "
                       "regressed; 2: a run cannot be read, a soak run given with a conformance run, or bad arguments.",
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("runs", nargs="+", metavar="RUN",
                   help="a run's report directory (reports/<timestamp>, reports/latest) or its results.json; two or more, "
                        "oldest first")
    p.add_argument("--html", metavar="OUT", help="write the comparison as a self-contained HTML page")
    p.add_argument("--json", metavar="OUT", help="write the comparison as JSON")
    p.add_argument("--margin-threshold", type=_percent, default=compare.DEFAULT_THRESHOLD, metavar="PCT",
                   help=f"a timing margin counts as shrunk when it fell by more than PCT %% of its earlier value (and by more "
                        f"than the runs' stated timing error); default {compare.DEFAULT_THRESHOLD * 100:g}")
    p.set_defaults(handler=_check_count)


def _check_count(args: argparse.Namespace) -> int:
    if len(args.runs) < 2:
        print("ckesc compare: error: give two runs or more (see ckesc compare --help)", file=sys.stderr)
        return ExitStatus.USAGE
    check_file(args.json, "--json")
    check_file(args.html, "--html")
    return _run_compare(args)
