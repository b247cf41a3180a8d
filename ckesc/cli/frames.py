"""``ckesc frames``: the frame catalogue, as a table or as JSON lines."""

from __future__ import annotations

import argparse
import json
from typing import Any

from ..protocol import catalogue as cat
from ..protocol.frame import FALLBACK_PRIORITY
from ..reporting.exits import ExitStatus


def _frame_rows() -> list[dict[str, Any]]:
    rows = []
    for s in cat.CATALOGUE:
        rows.append(
            {
                "id": s.type_id,
                "name": s.name,
                "kind": s.kind_label,
                "priority": None if s.priority is None else int(s.priority),
                "priority_name": None if s.priority is None else s.priority.name,
                "section": s.section,
                "title": s.title,
            }
        )
    return rows


def _run_frames(args: argparse.Namespace) -> int:
    rows = _frame_rows()
    if args.json:
        for row in rows:
            print(json.dumps(row))
        return ExitStatus.OK
    table = [("ID", "NAME", "KIND", "PRIORITY", "SECTION", "TITLE")]
    for r in rows:
        prio = "-" if r["priority"] is None else f"{r['priority_name']} ({r['priority']})"
        table.append((str(r["id"]), r["name"], r["kind"], prio, r["section"], r["title"]))
    widths = [max(len(row[i]) for row in table) for i in range(len(table[0]) - 1)]
    for row in table:
        print("  ".join(cell.ljust(w) for cell, w in zip(row, widths)) + "  " + row[-1])
    print(f"\n'-': the table lists no priority (F5: OBSERVE); encode uses {FALLBACK_PRIORITY.name} ({int(FALLBACK_PRIORITY)}).")
    return ExitStatus.OK


def add_frames_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("frames", help="list the frame catalogue", description="List every frame of the CKESC 2.1 catalogue.")
    p.add_argument("--json", action="store_true", help="one JSON object per frame")
    p.set_defaults(handler=_run_frames)
