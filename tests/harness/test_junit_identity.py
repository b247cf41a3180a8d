"""The run's identity on every JUnit testsuite, read back with an independent JUnit reader (junitparser),
and classnames that Jenkins' and GitLab's readers take as one package with a class per section (issue #12)."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from junitparser import JUnitXml

import ckesc
from ckesc.protocol.requirements import SECTION_TITLES
from ckesc.reporting.report import classname, git_revision, suite_properties

pytestmark = pytest.mark.xdist_group(__name__)  # its module-scoped runs are made once: its tests share one worker

REPO = Path(ckesc.__file__).resolve().parents[1]
SAFE = re.compile(r"ckesc\.[a-z][a-z0-9_]*")  # one dot: Jenkins' package "ckesc", a class per section


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> Path:
    reports = tmp_path_factory.mktemp("junit")
    subprocess.run([sys.executable, "-m", "ckesc", "run", "-q", "--reports", str(reports), "--", "-k",
                    "test_s4_4_2_msg_control or test_s4_4_26"], capture_output=True, text=True, timeout=600)
    runs = [p for p in reports.iterdir() if p.is_dir() and not p.is_symlink()]
    assert len(runs) == 1, runs
    return runs[0]


def test_every_testsuite_carries_the_runs_identity(run):
    info = json.loads((run / "results.json").read_text())["info"]
    esc = info["esc_information"]
    suites = list(JUnitXml.fromfile(str(run / "junit.xml")))
    assert len(suites) > 2, "the run's sections and the not-run tests' suite"
    for suite in suites:
        props = {p.name: p.value for p in suite.properties()}
        for field, value in esc.items():  # ESC Information 240, every field
            assert props[f"esc_information.{field}"] == str(value), (suite.name, field)
        assert props["firmware_date"] == f"20{esc['firmware_year']:02d}-{esc['firmware_month']:02d}-{esc['firmware_day']:02d}"
        assert (props["node_id"], props["profile"], props["lane"], props["bitrate"], props["power"]) == (
            str(info["node_id"]), info["profile"], "simulated", str(info["bitrate"]), "emulator")
        assert float(props["timing_error_s"]) == info["timing_error_s"] == 0.0
        assert props["suite_version"] == ckesc.__version__
        assert props["run_id"] == run.name == info["run_id"]
        assert props["complete"] == "False" and props["incomplete"].startswith("subset")
        assert props["git_revision"] == (info["git_revision"] or "none")
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "HEAD"], capture_output=True, text=True)
    if head.returncode == 0 and (REPO / ".git").exists():  # run from this checkout: its commit, "-dirty" with changes
        assert info["git_revision"].removesuffix("-dirty") == head.stdout.strip()


def test_classnames_make_one_package_with_a_class_per_section(run):
    cases = [case for suite in JUnitXml.fromfile(str(run / "junit.xml")) for case in suite]
    assert any(c.is_skipped for c in cases), "the not-run tests are there too"
    for case in cases:
        assert SAFE.fullmatch(case.classname), case.classname
        package, _, cls = case.classname.rpartition(".")  # how Jenkins' CaseResult splits it
        assert package == "ckesc" and cls
    ran = {case.classname for case in cases if not case.is_skipped}
    assert ran == {"ckesc.s4_4_2_msg_control", "ckesc.s4_4_26_esc_information"}
    every = {classname(s) for s in SECTION_TITLES}
    assert len(every) == len(SECTION_TITLES) and all(SAFE.fullmatch(c) for c in every), "one class per section"
    assert classname("4.4.22") == "ckesc.s4_4_22_set_get_freq" and classname("") == "ckesc.unselected"


def test_git_revision_is_none_outside_a_checkout_never_an_error(tmp_path, monkeypatch):
    assert git_revision(tmp_path) is None  # installed from a wheel: no .git beside the package
    (tmp_path / ".git").write_text("gitdir: /nowhere\n")
    assert git_revision(tmp_path) is None
    monkeypatch.setenv("PATH", str(tmp_path))  # no git program at all
    assert git_revision(REPO) is None


def test_unknown_identity_reads_as_none_or_no_answer():
    props = suite_properties({"git_revision": None, "esc_information": None, "complete": True})
    assert props == {"git_revision": "none", "esc_information": "no answer", "complete": "True"}


def test_results_json_has_each_tests_measurements_as_junit_does(run):
    """docs/reports.md promises results.json's ``measurements`` (issue #29: it had only the ``measurement.<n>.<key>``
    properties): a list per test, in order, the same as JUnit's properties of that test case."""
    results = json.loads((run / "results.json").read_text())["results"]
    cases = [{p.get("name"): p.get("value") for p in case.iter("property")}
             for case in ET.parse(run / "junit.xml").getroot().iter("testcase")]
    junit = {props["nodeid"]: props for props in cases if "nodeid" in props}
    measured = [r for r in results if r["measurements"]]
    assert measured, "4.4.2's tests measure answer delays"
    for r in results:
        props = junit[r["nodeid"]]
        assert r["measurements"] == [{key: props[f"measurement.{n}.{key}"] for key in m}
                                     for n, m in enumerate(r["measurements"])]
        assert len(r["measurements"]) == len({k.split(".")[1] for k in props if k.startswith("measurement.")})
    assert {"name", "value", "limit", "verdict"} <= set(measured[0]["measurements"][0])
