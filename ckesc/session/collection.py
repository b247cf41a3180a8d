"""Collection and preflight: which tests are the conformance suite's, what each cites, the check that every one
cites known requirements, and the preflight that ends a mistaken set-up before pytest's header (:func:`preflight`)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from ..bench.errors import PreflightError
from ..bench.outcomes import NotClaimed
from ..bench.profile import DutProfile
from ..protocol import functions
from ..protocol.requirements import REQUIREMENTS, requirement, section_heading
from . import preflight as checks
from .state import state

CONFORMANCE_PACKAGE = "conformance"
_PREFLIGHT_DONE = pytest.StashKey[bool]()


def is_conformance(item: pytest.Item) -> bool:
    mod = getattr(item, "module", None)
    return mod is not None and (mod.__name__.split(".")[0] == CONFORMANCE_PACKAGE)


def item_requirements(item: pytest.Item) -> list[str]:
    ids: list[str] = []
    for m in item.iter_markers("requirement"):
        ids.extend(m.args)
    return list(dict.fromkeys(ids))


def section_of(item: pytest.Item) -> str:
    ids = item_requirements(item)
    return getattr(getattr(item, "module", None), "SECTION", None) or (requirement(ids[0]).section if ids else "")


def section_title(item: pytest.Item) -> str:
    return section_heading(section_of(item))


def lacking(item: pytest.Item, profile: DutProfile) -> tuple[str, str] | None:
    """(requirement id, capability) of the first requirement ``item`` cites whose capability the profile lacks."""
    for rid in item_requirements(item):
        cap = requirement(rid).capability
        if cap and not profile.has(cap):
            return rid, cap
    return None


def check_claims(item: pytest.Item, profile: DutProfile) -> None:
    """A test of a function the profile declares absent is SKIPPED before it starts: not claimed (R9b)."""
    absent = functions.of_requirements(item_requirements(item), profile.absent)
    if absent:
        raise NotClaimed(absent[0].name, profile.name)


def conformance_dir() -> Path | None:
    """The installed ``conformance`` package's directory (a checkout, or site-packages of a wheel)."""
    spec = importlib.util.find_spec(CONFORMANCE_PACKAGE)
    locations = list(spec.submodule_search_locations or []) if spec else []
    return Path(locations[0]).resolve() if locations else None


def targets_conformance(config: pytest.Config) -> bool:
    """Whether the command line names the conformance suites (``--pyargs conformance[.module]``, or a
    path inside the package), so that set-up mistakes are found before pytest even collects."""
    where = conformance_dir()
    for arg in config.args:
        head = arg.split("::")[0]
        if config.option.pyargs and head.split(".")[0] == CONFORMANCE_PACKAGE:
            return True
        path = Path(head).resolve()
        if where is not None and (path == where or where in path.parents):
            return True
    return False


_PROVEN = pytest.StashKey[bool]()


def preflight(config: pytest.Config) -> None:
    """The preflight (:mod:`.preflight`), once per session: a mistake is a ``pytest.UsageError`` naming it. A batch's
    worker calls it itself, so that its bench's mistake is that bench's and not a crash (``ckesc/rigs/batch.py``)."""
    if config.stash.get(_PREFLIGHT_DONE, False):
        return
    config.stash[_PREFLIGHT_DONE] = True
    try:
        station = checks.run(config)
    except PreflightError as exc:
        raise pytest.UsageError(f"preflight: {exc}") from None
    st = state(config)
    st.station, st.profile = station, station.profile
    if config.getoption("power") == "labgrid" and station.power is not None:
        st.info["power_labgrid"] = getattr(station.power, "where", station.power.name)


@pytest.hookimpl(tryfirst=True)
def pytest_sessionstart(session: pytest.Session) -> None:
    """Set-up mistakes end the run here, before pytest's header, collection or any report."""
    if targets_conformance(session.config):
        preflight(session.config)


def pytest_deselected(items: list[pytest.Item]) -> None:
    if items:
        st = state(items[0].config)
        st.deselected += [it.nodeid for it in items if is_conformance(it)]


def pytest_collection_finish(session: pytest.Session) -> None:
    st = state(session.config)
    st.selected = [it for it in session.items if is_conformance(it)]
    if st.selected:
        preflight(session.config)  # collected from a path the command line did not name as the suites
        bench_proof(session.config, st.selected)


def cycles_power(items: list[pytest.Item]) -> bool:
    """Whether a test of ``items`` may cycle the DUT's power (marker ``power_cycle`` or ``may_power_cycle``)."""
    return any(it.get_closest_marker("power_cycle") or it.get_closest_marker("may_power_cycle") for it in items)


def bench_proof(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The bench proven before any test (:meth:`~ckesc.bench.station.Station.prove`), once, with its power switch
    where a selected test may cycle power, and the profile's defaults a real bus takes: said on the console and kept
    for the reports (``info["bench"]``); a failure is a ``pytest.UsageError`` (exit 2, no report), as the
    preflight's."""
    if config.stash.get(_PROVEN, False):
        return
    config.stash[_PROVEN] = True
    st = state(config)
    try:
        proven = st.station.prove(cycles_power=cycles_power(items)) if st.station is not None else []
        said = [*(st.profile.defaults_taken if st.profile else ()), *proven]
    except PreflightError as exc:
        raise pytest.UsageError(f"preflight: {exc}") from None
    if st.station is not None and st.station.firmware is not None:  # the image flashed and proven (--firmware)
        st.info["firmware"] = st.station.firmware
    if said:
        st.info["bench"] = said
        tr = config.pluginmanager.get_plugin("terminalreporter")
        for line in said:
            if tr is not None:
                tr.write_line(f"ckesc: {line}")


def pytest_collection_modifyitems(session: pytest.Session, config: pytest.Config, items: list[pytest.Item]) -> None:
    st = state(config)
    problems = []
    for item in items:
        if not is_conformance(item):
            continue
        st.conformance = True
        ids = item_requirements(item)
        if not ids:
            problems.append(f"{item.nodeid}: no @pytest.mark.requirement(...)")
        for i in ids:
            if i not in REQUIREMENTS:
                problems.append(f"{item.nodeid}: unknown requirement id {i!r}")
    if problems:
        raise pytest.UsageError("conformance tests must cite known requirements:\n  " + "\n  ".join(problems))
    # run-wide checks (4.1 framing over every frame of the run) go last
    items.sort(key=lambda it: 1 if it.get_closest_marker("last") else 0)
