"""The skeleton of ``ckesc compare``, whatever the runs' kind (the suite's runs, :mod:`.compare`; soak runs,
:mod:`.soak_compare`): reading a record, the runs' letters, each run compared with the one before it, the flags of a
comparison that is not like for like, the console's first and last lines and the HTML page's frame. A kind brings
its facts of one run, its diff of two runs and its tables. Only :func:`read_doc` touches the file system.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Callable, Sequence

from .htmlkit import CSS, badge, e

EXTRA_CSS = """
.v-NO-REGRESSION{background:#1a7f37}.v-NOT-RUN{background:#6e7781}
tr.diff>td:not(.cell),tr.diff>th{background:#fff8c5}#identity table{width:100%;table-layout:fixed}td{overflow-wrap:anywhere}
.num,.lim,.chg td.vv{white-space:nowrap}.num{text-align:right;font-variant-numeric:tabular-nums}.what{min-width:16rem}
.matrix td.cell{text-align:center;font-size:.8rem;font-weight:600}.matrix tr.group th{background:#eaeef2;text-align:left}
.matrix td.c-NOT-CHECKED{color:#afb8c1}.trend td{font-size:.8rem}.trend td.spark{padding:0;width:10rem}
.chg td{font-size:.85rem}details{margin:.4rem 0}summary{cursor:pointer;font-weight:600}
"""


class RunError(Exception):
    """A run that cannot be read: one line saying which and why."""


def read_doc(path: str | Path) -> tuple[str, Any]:
    """The parsed ``results.json`` at ``path`` (a run's directory or the file) and the run's label (its directory's
    name): a conformance run's or a soak run's. Raises :class:`RunError`."""
    p = Path(path)
    if p.is_dir():
        if not (p / "results.json").is_file():
            hint = " (that is the reports directory: give one run, e.g. reports/latest)" if (p / "latest").exists() else ""
            raise RunError(f"{path}: no results.json in this directory{hint}")
        label, p = p.resolve().name, p / "results.json"
    elif p.is_file():
        label = p.resolve().parent.name
    else:
        raise RunError(f"{path}: no such run directory or results.json")
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise RunError(f"{path}: cannot read {p}: {exc.strerror}") from None
    except (UnicodeDecodeError, ValueError) as exc:
        raise RunError(f"{path}: {p.name} is not JSON: {exc}") from None
    return label, doc


def is_soak(doc: Any) -> bool:
    """``doc`` (a parsed results.json) is a ``ckesc soak`` record."""
    return isinstance(doc, dict) and doc.get("kind") == "soak"


def letter(i: int) -> str:
    """The ``i``-th run's letter (A, B, ...; R27 on)."""
    return chr(ord("A") + i) if i < 26 else f"R{i + 1}"


def comparison(runs: Sequence[Any], diff: Callable[[Any, Any], dict[str, Any]], run_row: Callable[[Any], dict[str, Any]],
               flags: list[str], **facts: Any) -> dict[str, Any]:
    """Two or more runs, oldest first, as one JSON-ready dict: each run's row (with its letter), the flags, each run
    compared with the one before it (``diff``, whose dict says whether it ``regressed``), the kind's other
    ``facts``, and whether any pair regressed."""
    if len(runs) < 2:
        raise ValueError("compare needs two runs or more")
    pairs = [diff(a, b) for a, b in zip(runs, runs[1:])]
    return {"runs": [{"letter": letter(i), **run_row(r)} for i, r in enumerate(runs)], "flags": flags, "pairs": pairs,
            **facts, "regressed": any(p["regressed"] for p in pairs)}


def differs(what: str, values: list[Any], unknown: str = "?") -> list[str]:
    """The flag of a fact the runs do not share, one line (none when they share it): ``different lanes: A sim, B
    vcan0``. A run that does not say (None) is not told apart, and is shown as ``unknown``."""
    if len({str(v) for v in values if v is not None}) < 2:
        return []
    return [f"different {what}: " + ", ".join(f"{letter(i)} {unknown if v is None else v}" for i, v in enumerate(values))]


def pair_name(doc: dict[str, Any], i: int) -> str:
    """The ``i``-th pair of the comparison ``doc``: ``A -> B``."""
    return f"{doc['runs'][i]['letter']} -> {doc['runs'][i + 1]['letter']}"


def first_line(doc: dict[str, Any], kind: str = "") -> str:
    """The console's first line: how many runs, and how they are compared."""
    return f"ckesc compare: {len(doc['runs'])} {kind + ' ' if kind else ''}runs, oldest first; each compared with the one before it"


def last_line(doc: dict[str, Any], summary: Callable[[dict[str, Any]], str]) -> str:
    """The console's last line: each pair that regressed with its ``summary``, or that nothing did."""
    if not doc["regressed"]:
        return "no regression"
    return "REGRESSED: " + "; ".join(f"{pair_name(doc, i)}: {summary(p)}" for i, p in enumerate(doc["pairs"]) if p["regressed"])


def page(doc: dict[str, Any], *, heading: str, lead: str, body: list[str], title: str = "") -> str:
    """The comparison as one self-contained HTML page, in report.html's style: its heading, the overall badge with
    ``lead``, the flags as banners, then ``body`` (HTML)."""
    overall = "REGRESSED" if doc["regressed"] else "NO REGRESSION"
    return (f"<!DOCTYPE html>\n<html lang=en><head><meta charset=utf-8><title>{e(title or heading)}</title><style>{CSS}"
            f"{EXTRA_CSS}</style></head><body>\n<header><h1>{e(heading)}</h1><p class=run>{badge(overall)} {e(lead)}</p>"
            + "".join(f"<p class=banner role=alert>{e(f)}</p>" for f in doc["flags"]) + "</header>\n"
            + "\n".join(body) + "\n</body></html>\n")
