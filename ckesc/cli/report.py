"""``ckesc report``: its argument and exit code; :mod:`ckesc.reporting.html_report` builds the page."""

from __future__ import annotations

from pathlib import Path

from ..reporting.exits import ExitStatus
from ..reporting.html_report import build
from .common import UsageError, check_file


def add_report_command(sub) -> None:
    p = sub.add_parser("report", help="(re)build report.html of a run from its results.json",
                       description="Build REPORT_DIR/report.html from REPORT_DIR/results.json (what `ckesc run` wrote), "
                                   "e.g. after an upgrade, or for a run copied from another machine.")
    p.add_argument("report_dir", metavar="REPORT_DIR", help="a run's directory, e.g. reports/latest")
    p.set_defaults(handler=_report_command)


def _report_command(args) -> int:
    out = Path(args.report_dir)
    if not (out / "results.json").is_file():
        raise UsageError(f"no results.json in {out} (give a run's directory, e.g. reports/latest)")
    check_file(str(out / "report.html"), "REPORT_DIR", "report page")
    try:
        path = build(out)
    except (ValueError, KeyError, TypeError, AttributeError) as exc:  # JSONDecodeError is a ValueError
        raise UsageError(f"{out / 'results.json'} is not a results record this version reads: {exc!r}") from None
    print(path)
    return ExitStatus.OK
