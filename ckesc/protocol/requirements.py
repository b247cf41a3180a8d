"""The requirements table (``requirements.toml`` beside this file), loaded once.

Every conformance test names the requirement ids it checks with ``@pytest.mark.requirement(...)``;
the report groups results by section and shows which requirements are covered.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from enum import StrEnum
from importlib import resources
from types import MappingProxyType

from .catalogue import CATALOGUE

#: a requirement's strength, strongest first (a failure message leads with the strongest broken one)
STRENGTHS = ("SHALL", "READING", "OBSERVE")


class Verdict(StrEnum):
    """What a test can come out as: SHALL / READING tests PASS or FAIL, OBSERVE ones are OBSERVED. A
    ``str``: it compares equal to, and is written as, its name."""

    PASS = "PASS"
    FAIL = "FAIL"
    INCONCLUSIVE = "INCONCLUSIVE"
    OBSERVED = "OBSERVED"
    SKIPPED = "SKIPPED"
    ERROR = "ERROR"


VERDICTS = tuple(Verdict)

#: each verdict in a table's narrow column (summary.txt, the console, ``ckesc compare``), and the legend that says them
VERDICT_SHORT = MappingProxyType({Verdict.PASS: "PASS", Verdict.FAIL: "FAIL", Verdict.INCONCLUSIVE: "INC",
                                  Verdict.OBSERVED: "OBS", Verdict.SKIPPED: "SKIP", Verdict.ERROR: "ERR"})
VERDICT_LEGEND = ", ".join(f"{short} {v}" for v, short in VERDICT_SHORT.items() if short != v.value)


def section_key(section: str) -> tuple:
    """Sort key of a section number in the document's order ("4.4.2" before "4.4.10")."""
    return tuple(int(p) if p.isdigit() else 999 for p in section.replace("-", ".").split("."))

#: Section titles as the document's contents page names them.
SECTION_TITLES = MappingProxyType(
    {
        "1": "Scope of application",
        "4.1": "UAVCAN protocols (framing)",
        "4.1.1": "Conceptual",
        "4.1.2": "ID field",
        "4.1.3": "CAN payload",
        "4.2": "CAN ESC working mechanism",
        "4.2.1": "Functionality",
        "4.3": "List of data frame types",
        "4.3.1": "ID domain assignment",
        "4.3.2": "Data frame type table",
        "attachment": "Fault code definitions",
        **{s.section: s.title for s in reversed(CATALOGUE)},  # a shared section (4.4.25) takes its first frame's title
        "4.4.8": "MSG_EXP2-6",
        "robustness": "Malformed, foreign frames, a loaded bus",
        "soak": "Long runs (ckesc soak)",
    }
)


def section_heading(section: str) -> str:
    """``4.4.22 Set/Get Freq``: a section's number and its title, as the reports and the console name it."""
    return f"{section} {SECTION_TITLES.get(section, '')}".strip()


@dataclass(frozen=True)
class Requirement:
    id: str
    strength: str
    section: str
    quote: str
    note: str = ""
    capability: str | None = None
    #: what judges it: the conformance suite (a test must cite it), or ``soak`` (hours of running: ``ckesc soak``'s
    #: watches, R19, which no ten-minute test can judge)
    judged_by: str = "suite"

    @property
    def title(self) -> str:
        return SECTION_TITLES.get(self.section, self.section)


def _load() -> dict[str, Requirement]:
    text = resources.files(__package__).joinpath("requirements.toml").read_text(encoding="utf-8")
    out: dict[str, Requirement] = {}
    for row in tomllib.loads(text)["requirement"]:
        req = Requirement(**row)
        if req.strength not in STRENGTHS:
            raise ValueError(f"requirement {req.id}: unknown strength {req.strength!r}")
        if req.id in out:
            raise ValueError(f"requirement {req.id} listed twice")
        out[req.id] = req
    return out


REQUIREMENTS = MappingProxyType(_load())


def requirement(req_id: str) -> Requirement:
    try:
        return REQUIREMENTS[req_id]
    except KeyError:
        raise KeyError(f"unknown requirement id {req_id!r} (see ckesc/protocol/requirements.toml)") from None


def strongest(ids) -> str:
    """The strength a test takes from the requirements it checks: the strongest one."""
    strengths = {requirement(i).strength for i in ids}
    for s in STRENGTHS:
        if s in strengths:
            return s
    return "OBSERVE"
