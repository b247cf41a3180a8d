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
    cited = cited_ids()
    missing = sorted(rid for rid, req in REQUIREMENTS.items() if req.strength != "OBSERVE" and rid not in cited)
    assert not missing, f"SHALL/READING requirements no conformance test cites: {missing}"


@pytest.mark.parametrize("fault", sorted(FAULTS))
def test_fault_names_known_requirements(fault):
    unknown = [r for r in FAULTS[fault].rules if r not in REQUIREMENTS]
    assert not unknown, f"fault {fault} names rules missing from requirements.toml: {unknown}"


def test_strongest_strength_decides():
    assert strongest(["R10-answer", "R10"]) == "SHALL"
    assert strongest(["R4", "R6"]) == "READING"
    assert strongest(["R6"]) == "OBSERVE"
