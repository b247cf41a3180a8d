"""The requirements table and the suites agree: every SHALL/READING requirement has a test, every
cited id exists, every fault names known requirements."""

import pytest

from ckesc.emulator.faults import FAULTS
from ckesc.protocol.requirements import REQUIREMENTS, STRENGTHS, strongest
from ckesc.selftest import citations


def cited_ids() -> dict[str, set[str]]:
    """requirement id -> conformance tests citing it, read from the modules' source (no pytest run)."""
    return citations()


def test_requirements_table_is_well_formed():
    assert len(REQUIREMENTS) > 100
    for req in REQUIREMENTS.values():
        assert req.strength in STRENGTHS, req
        assert req.quote.strip(), f"{req.id} has no quote"


def test_every_cited_id_exists():
    unknown = sorted(set(cited_ids()) - set(REQUIREMENTS))
    assert not unknown, f"tests cite unknown requirement ids: {unknown}"


def test_every_shall_and_reading_requirement_has_a_test():
    """... but those of long runs (section "soak": R19), which ``ckesc soak`` checks over hours, not a test of the
    ten-minute suite; the emulator's soak faults break them (tests/emulator/test_soak_faults.py)."""
    cited = cited_ids()
    # a requirement judged over hours (R19: ``judged_by = "soak"``) is ckesc soak's, tested in tests/soak
    missing = sorted(rid for rid, req in REQUIREMENTS.items()
                     if req.strength != "OBSERVE" and req.judged_by == "suite" and rid not in cited)
    assert not missing, f"SHALL/READING requirements no conformance test cites: {missing}"


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_fault_names_known_requirements(fault):
    unknown = [r for r in FAULTS[fault].rules if r not in REQUIREMENTS]
    assert not unknown, f"fault {fault} names rules missing from requirements.toml: {unknown}"


def test_strongest_strength_decides():
    assert strongest(["R10-answer", "R10"]) == "SHALL"
    assert strongest(["R4", "R6"]) == "READING"
    assert strongest(["R6"]) == "OBSERVE"


def test_every_requirement_id_written_in_the_code_exists():
    """A string that reads as a requirement id (F4, R9a, R15-payload, 4.4.2-3, 4.4.5-T, A-1) anywhere in the package
    or the suites names one of requirements.toml: a typo is caught here, not read as an unknown (OBSERVE) rule."""
    import ast
    import re
    from pathlib import Path

    import ckesc
    import conformance

    shaped = re.compile(r"^(F\d+|R\d+[a-z]?(-[\w-]+)?|\d+(\.\d+)+-\w+|A-\d+)$")
    unknown = [f"{path.name}:{node.lineno}: {node.value}"
               for root in (Path(ckesc.__file__).parent, Path(conformance.__file__).parent)
               for path in sorted(root.rglob("*.py"))
               for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
               if isinstance(node, ast.Constant) and isinstance(node.value, str) and shaped.match(node.value)
               and node.value not in REQUIREMENTS]
    assert unknown == [], unknown
