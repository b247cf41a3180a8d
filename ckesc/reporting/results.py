"""The results of a run as the reports read them."""

from __future__ import annotations

from typing import Any


def incomplete_banner(info: dict[str, Any]) -> str:
    """One line saying why a run is less than the whole suite ("" for a complete one)."""
    why = info.get("incomplete") or ""
    if not why:
        return ""
    kind = why.split(":")[0].split(" ")[0].upper()
    kind = {"STOPPED": "INCOMPLETE"}.get(kind, kind)
    return f"{kind} - not a conformance result for the whole suite: {why}; {info.get('not_run', 0)} tests not run"


def claim_text(info: dict[str, Any]) -> str:
    """What the conformance claim leaves out (R9b: functions the DUT profile declares absent)."""
    left_out = info.get("not_claimed") or ""
    if not left_out:
        return "claim: every function of the document (the DUT profile declares none absent, R9b)"
    return f"claim: leaves out (declared absent by the DUT profile, R9b; their tests SKIPPED): {left_out}"
