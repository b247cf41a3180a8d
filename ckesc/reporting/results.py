"""The results of a run, as ``results.json`` holds them and every report reads them: one :class:`Result` per
test, the run's :class:`RunInfo`, and :class:`RunRecord`, the whole file, which writes and reads it."""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, TypedDict

from ..protocol.requirements import REQUIREMENTS, Verdict

#: how a requirement's result is drawn from its tests' verdicts: the first that occurs
WORST_FIRST = (Verdict.FAIL, Verdict.ERROR, Verdict.INCONCLUSIVE, Verdict.PASS, Verdict.OBSERVED, Verdict.SKIPPED)
#: a requirement no test of the run checked
NOT_CHECKED = "NOT CHECKED"


def requirement_result(outcomes: Iterable[str]) -> str:
    """A requirement's (or a section's) result from its tests' verdicts: the worst (:data:`WORST_FIRST`), or
    :data:`NOT_CHECKED` when there are none."""
    outcomes = set(outcomes)
    return next((v for v in WORST_FIRST if v in outcomes), NOT_CHECKED)


def broken_requirements(r: Result) -> list[str]:
    """The requirements a test's evidence broke, as its record names them: for a FAIL, those of what it broke
    (``broken``: the failed assert's and every failed limit's) and the bus rules it broke; for any other verdict, the
    bus rules broken while it ran. A broken requirement that names no id cites every requirement of the test of its
    strength, and a FAIL that records nothing broken (an exception in the test) all of them."""
    broken = list(r.bus_rules)
    if r.outcome != Verdict.FAIL:
        return list(dict.fromkeys(broken))
    for b in r.broken:
        ids = b["requirements"] or [i for i in r.requirements if i in REQUIREMENTS and REQUIREMENTS[i].strength == b["strength"]]
        broken += ids or r.requirements
    if not r.broken and not r.bus_rules:
        broken += r.requirements
    return list(dict.fromkeys(broken))


def measurements(properties: Mapping[str, str]) -> list[dict[str, str]]:
    """A test's measurements (name, value, limit, margin, clock, error, verdict), in order, from its
    ``measurement.<n>.<key>`` properties."""
    found: dict[int, dict[str, str]] = defaultdict(dict)
    for key, value in properties.items():
        parts = key.split(".")
        if len(parts) == 3 and parts[0] == "measurement" and parts[1].isdigit():
            found[int(parts[1])][parts[2]] = value
    return [found[i] for i in sorted(found)]


@dataclass
class Result:
    """One test's result, as results.json, JUnit and the HTML report write it."""

    nodeid: str
    name: str
    section: str
    requirements: list[str]
    strength: str
    outcome: str = Verdict.PASS  # a Verdict
    message: str = ""
    duration: float = 0.0
    lane_seconds: float = 0.0  # lane time the test took: in the simulated lane, the waits the protocol imposes
    properties: dict[str, str] = field(default_factory=dict)
    observations: list[tuple[str, str]] = field(default_factory=list)
    #: the test's CAN traces by lane ("": the DUT's, "bench": multi_dut's private bench), relative to the
    #: run's report directory; a lane that heard no frame during the test has none
    traces: dict[str, str] = field(default_factory=dict)
    #: what the test's traffic shows, for the HTML report's plots (answer delays, report intervals, R8
    #: timeline): see evidence.timing
    evidence: dict[str, Any] = field(default_factory=dict)
    #: requirement ids of the bus rules (ckesc/evidence) the traffic broke while the test ran: such a test
    #: FAILs, quoting the frames, and these ids are what it cites besides its own
    bus_rules: list[str] = field(default_factory=list)
    #: the distinct problems among those violations (evidence.live.causes: a stable key per problem, its
    #: title, rules, node, how often among the quoted ones, its first occurrence): report.html, summary.txt
    #: and the console group the run's failures by them
    bus_causes: list[dict[str, Any]] = field(default_factory=list)
    #: what the test itself broke (not the bus rules), the strongest first: each its ``requirements`` (none named: the
    #: test's own of that strength), ``strength`` and ``text`` (what the DUT did) (:class:`~ckesc.bench.outcomes.Broken`);
    #: ``message`` is their rendering
    broken: list[dict[str, Any]] = field(default_factory=list)
    #: the test's measurements as numbers: name, value, unit, limit, op, margin, clock, error, verdict, requirement
    #: (:meth:`~ckesc.bench.outcomes.Measurement.as_json`; ``properties`` has them rendered, for JUnit)
    measured: list[dict[str, Any]] = field(default_factory=list)

    @property
    def measurements(self) -> list[dict[str, str]]:
        """The test's measurements (:func:`measurements`)."""
        return measurements(self.properties)

    def to_json(self) -> dict[str, Any]:
        """As results.json holds it: its fields, in order, its ``measurements`` (read from ``properties``,
        where JUnit has them too) and ``broken_requirements`` (:func:`broken_requirements`); :meth:`from_json`
        leaves those two out again."""
        return {**self.__dict__, "measurements": self.measurements, "broken_requirements": broken_requirements(self)}

    @classmethod
    def from_json(cls, record: Mapping[str, Any]) -> Result:
        """A record of results.json (an older one may lack the later fields: they take their defaults, and an older
        FAIL's ``broken`` is its recorded ``broken_requirements``, :func:`_broken_of_old`); a key this version does not
        know is left out. KeyError when a required one (nodeid, name, section, requirements, strength) is missing,
        ValueError for an unknown outcome."""
        known = {f.name for f in fields(cls)}
        r = cls(**{k: v for k, v in record.items() if k in known})
        r.outcome = Verdict(r.outcome)
        r.observations = [tuple(o) for o in r.observations]  # type: ignore[misc]
        if "broken" not in record:
            r.broken = _broken_of_old(r, record.get("broken_requirements"))
        return r


def _broken_of_old(r: Result, recorded: list[str] | None) -> list[dict[str, Any]]:
    """What a FAIL recorded before ``broken`` was a field broke: the requirements its record listed as broken (all it
    cites when it listed none), but the bus rules', at the test's strength, its message's first line the text. A
    FAIL of the bus rules alone (its message begins ``[bus rules``) broke nothing of its own."""
    own = [i for i in recorded or r.requirements if i not in r.bus_rules]
    if r.outcome != Verdict.FAIL or (r.message or "").startswith("[bus rules") or not own:
        return []
    return [{"requirements": own, "strength": r.strength, "text": (r.message or "").strip().split("\n", 1)[0]}]


class RunInfo(TypedDict, total=False):
    """The run's info (results.json's ``info``, JUnit's testsuite properties); every key is optional.

    The DUT and bench: ``dut`` (emulator / bus), ``lane``, ``clock`` (simulated, bus timestamp, host clock),
    ``profile``, ``node_id``, ``bitrate``, ``power``, ``power_labgrid``, ``faults`` and ``emulator_variants``
    (``emulator_variants_seed``) of an emulator, ``esc_information`` (ESC Information 240's fields; None: no
    answer), ``firmware`` (``--firmware``: the image, its ``sha256``, the ``flash_cmd`` and its ``flash_output``'s tail, what
    240 was ``expected`` to answer and ``answered``), ``not_claimed`` (the functions the profile declares absent, R9b), ``profile_warnings`` (its claims the DUT
    contradicted at the run's start) and ``profile_check`` (what the DUT was asked for them). Timing: ``timing_error_s`` (the
    bench's stated error), ``jitter_s`` (the DUT's allowance), ``interval_tolerance_ms`` (what the plots band),
    ``echo``, ``echo_note``, ``own_frames_clock``, ``own_frames_error_s`` (what times the host's own frames),
    ``first_reports_s``, ``readiness``. The run: ``order``, ``epochs``, ``cold_boots``, ``lane_seconds``,
    ``complete``, ``incomplete`` (why not: aborted / interrupted / subset ...), ``not_run`` (how many tests),
    ``not_restored``, ``bus_recoveries``, ``foreign_traffic`` (``--foreign-traffic``: what was played, the frames sent,
    the ``load`` they took and, in real time, how late they went out), ``run_frames_not_kept``, ``report_dir``; and written with the reports:
    ``run_id`` (the run directory's name), ``suite_version``, ``git_revision`` (None outside a checkout).
    """

    dut: str
    lane: str
    clock: str
    profile: str
    node_id: int
    bitrate: int
    power: str
    power_labgrid: dict[str, Any]
    faults: str
    emulator_variants: str
    emulator_variants_seed: int | None
    esc_information: dict[str, Any] | None
    firmware: dict[str, str]
    not_claimed: str
    profile_warnings: list[str]
    profile_check: str
    timing_error_s: float
    jitter_s: float
    interval_tolerance_ms: float
    echo: bool
    echo_note: str
    own_frames_clock: str
    own_frames_error_s: float
    first_reports_s: dict[str, Any]
    readiness: Any
    order: str
    epochs: list[Any]
    cold_boots: list[Any]
    lane_seconds: float
    complete: bool
    incomplete: str
    not_run: int
    not_restored: Any
    bus_recoveries: list[str]
    foreign_traffic: dict[str, Any]
    run_frames_not_kept: int
    report_dir: str
    run_id: str
    suite_version: str
    git_revision: str | None


def firmware_rows(info: Mapping[str, Any]) -> list[tuple[str, str]]:
    """The image under test (``info["firmware"]``, ``--firmware``) as (label, value) rows, in the words every report
    uses (the HTML header, summary.txt, ``ckesc compare``'s identity table); none without an image."""
    fw = info.get("firmware")
    if not isinstance(fw, Mapping):
        return []
    rows = [("firmware image", fw.get("image")), ("image SHA-256", fw.get("sha256")),
            ("240 expected", fw.get("expected")), ("240 answered", fw.get("answered")),
            ("flash command", fw.get("flash_cmd")), ("flash output", fw.get("flash_output"))]
    return [(k, str(v)) for k, v in rows if v not in (None, "")]


class NotRun(TypedDict, total=False):
    """A test the run did not get to (results.json's ``not_run``): its id, name, section, requirements, why."""

    nodeid: str
    name: str
    section: str
    requirements: list[str]
    reason: str


@dataclass
class RunRecord:
    """A run's ``results.json``: its info, coverage (which requirements a test checked), one :class:`Result` per
    test, the tests it did not get to and the bus rules broken outside a test's FAIL (``rule_failures``)."""

    info: RunInfo
    results: list[Result]
    not_run: list[NotRun] = field(default_factory=list)
    coverage: dict[str, Any] = field(default_factory=dict)
    rule_failures: list[dict[str, Any]] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {"info": self.info, "coverage": self.coverage, "results": [r.to_json() for r in self.results],
                "not_run": list(self.not_run), "rule_failures": self.rule_failures}

    def write(self, path: Path) -> None:
        path.write_text(json.dumps(self.to_json(), indent=1, default=str), encoding="utf-8")

    @classmethod
    def from_json(cls, doc: Any) -> RunRecord:
        """From a parsed results.json; ValueError, KeyError or TypeError when it is not one this version reads."""
        if not isinstance(doc, dict) or not isinstance(doc.get("results"), list) or not isinstance(doc.get("info"), dict):
            raise ValueError("not a results record: it needs an info object and a results list")
        return cls(info=doc["info"], results=[Result.from_json(r) for r in doc["results"]],
                   not_run=[n for n in doc.get("not_run") or [] if isinstance(n, dict)],
                   coverage=doc.get("coverage") or {}, rule_failures=doc.get("rule_failures") or [])

    @classmethod
    def read(cls, path: Path) -> RunRecord:
        """``path`` (a results.json): OSError, or ValueError (a JSONDecodeError too) / KeyError / TypeError."""
        return cls.from_json(json.loads(Path(path).read_text(encoding="utf-8")))


def incomplete_banner(info: Mapping[str, Any]) -> str:
    """One line saying why a run is less than the whole suite ("" for a complete one)."""
    why = info.get("incomplete") or ""
    if not why:
        return ""
    kind = why.split(":")[0].split(" ")[0].upper()
    kind = {"STOPPED": "INCOMPLETE"}.get(kind, kind)
    return f"{kind} - not a conformance result for the whole suite: {why}; {info.get('not_run', 0)} tests not run"


def claim_text(info: Mapping[str, Any]) -> str:
    """What the conformance claim leaves out (R9b: functions the DUT profile declares absent)."""
    left_out = info.get("not_claimed") or ""
    if not left_out:
        return "claim: every function of the document (the DUT profile declares none absent, R9b)"
    return f"claim: leaves out (declared absent by the DUT profile, R9b; their tests SKIPPED): {left_out}"


def profile_warnings(info: Mapping[str, Any]) -> list[str]:
    """One line per claim of the DUT profile the DUT contradicted at the run's start (``profile_warnings``: the
    profile checked as a conformance statement, ckesc/bench/statement.py); warnings, never a verdict."""
    return [f"WARNING: the DUT profile: {w}" for w in info.get("profile_warnings") or []]
