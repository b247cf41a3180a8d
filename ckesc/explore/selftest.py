"""How fast exploration finds each emulator fault: the self-test's "found within N programs / steps / seconds".

    rows = find_faults(["suspend_persisted", "intervals_not_persisted"], budget_s=120, seed=1)
    print(table(rows))

Each fault runs in a fresh emulated bench (the bench options given, the simulated lane by default) from the same
seed, until its first finding (shrunk), the budget or ``max_programs``. A fault is *found* when the finding cites a
rule the fault says it breaks; a finding citing none of them is listed too (found, but for another reason). A
fault added to the emulator plugs in by its name: nothing here knows any fault.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any, Callable, Iterable, Mapping

from ..emulator.faults import FAULTS
from ..protocol.requirements import REQUIREMENTS
from .engine import explore
from .runner import Session

#: R20's clauses (the bus as hardware): a fault that breaks one is explored with R20's bus steps
R20_CLAUSES = frozenset(r for r in REQUIREMENTS if r.startswith("R20-"))


@dataclass
class FaultRow:
    fault: str
    found: bool  # a finding citing one of the fault's rules
    programs: int | None  # programs run before the first that showed it
    steps: int | None
    seconds: float | None  # wall seconds of exploration before it
    lane_seconds: float | None
    shrunk_steps: int | None
    requirements: list[str]
    finding: str
    program: list[str]
    explored: str  # the exploration's stats line

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


def find_faults(faults: Iterable[str], *, budget_s: float = 120.0, seed: int = 1, max_programs: int | None = None,
                options: Mapping[str, Any] | None = None,
                progress: Callable[[FaultRow], None] | None = None, load: bool | None = None,
                shrink_s: float | None = None, bus: bool | None = None) -> list[FaultRow]:
    """``load``: whether programs draw foreign-load steps (R18; None: for a fault that breaks R18, which shows only
    on a loaded bus); ``bus``: R20's bus steps likewise (None: for a fault that breaks one of R20's clauses). ``shrink_s``: how long each finding is shrunk at most (None: what is left of the budget)."""
    rows = []
    for fault in faults:
        session = Session({**dict(options or {}), "emulator_faults": fault},
                          load="R18" in FAULTS[fault].rules if load is None else load,
                          bus=bool(R20_CLAUSES & set(FAULTS[fault].rules)) if bus is None else bus)
        try:
            found, stats = explore(session, budget_s=budget_s, seed=seed, database=None, stop_at_first=True,
                                   max_programs=max_programs, shrink_s=shrink_s)
        finally:
            session.close()
        if found:
            fd = found[0]
            f = fd.finding
            row = FaultRow(fault, bool(set(f.requirements) & set(FAULTS[fault].rules)), fd.programs_before, fd.steps_before,
                           round(fd.seconds_before, 2), round(fd.lane_seconds_before, 1), len(fd.program),
                           list(f.requirements), f.what, [a.describe() for a in fd.program], stats.line())
        else:
            row = FaultRow(fault, False, None, None, None, None, None, [], "", [], stats.line())
        rows.append(row)
        if progress is not None:
            progress(row)
    return rows


def table(rows: list[FaultRow]) -> str:
    out = ["| fault | found | within programs | steps | wall s | lane s | shrunk to | cites | finding |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        state = "yes" if r.found else ("other rule" if r.finding else "NO")
        out.append(f"| {r.fault} | {state} | {r.programs if r.programs is not None else '-'} | "
                   f"{r.steps if r.steps is not None else '-'} | {r.seconds if r.seconds is not None else '-'} | "
                   f"{r.lane_seconds if r.lane_seconds is not None else '-'} | "
                   f"{'; '.join(r.program) or '-'} | {' '.join(r.requirements) or '-'} | {r.finding or '-'} |")
    return "\n".join(out)
