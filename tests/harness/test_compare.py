"""``ckesc compare``: runs made by the emulator with and without faults, compared as the command does
(subprocesses, exit statuses, --json, --html rendered in headless Chromium), and the library's rules on
records derived from those runs (issue #12, items 5 and 6)."""

from __future__ import annotations

import copy
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

# the report's DOM reader and headless Chromium, as tests/harness/test_html_report.py uses them
from test_html_report import _chromium, _render

from ckesc.reporting import compare

pytestmark = pytest.mark.xdist_group(__name__)  # its module-scoped runs are made once: its tests share one worker

SELECTION = "test_s4_4_2_msg_control or test_s4_4_26"  # answer-delay margins (R2, 4.4.2-4) and ESC Information
FAULT = "answer_late"  # MSG Control answered after 80 ms: R2 and 4.4.2-4 FAIL


def ckesc(*args: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "ckesc", *map(str, args)], capture_output=True, text=True, timeout=600)


def _run(reports: Path, *args: str) -> Path:
    ckesc("run", "-q", "--reports", reports, *args, "--", "-k", SELECTION)
    assert (reports / "latest" / "results.json").is_file(), f"no run in {reports}"
    return reports / "latest"


#: another ESC model's profile, on the same (exact) bench: no LED, alone on its bus
OTHER_PROFILE = """[dut]
name = "another CKESC 2.1 ESC"
[capabilities]
led = false
motor = true
pwm_input = true
multi_node = false
"""


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("compare")
    other = base / "other-esc.toml"
    other.write_text(OTHER_PROFILE)
    return {"clean": _run(base / "clean"), "late": _run(base / "late", "--emulator-faults", FAULT),
            "generic": _run(base / "generic", "--profile", str(other))}


def _doc(run: Path) -> dict:
    return json.loads((run / "results.json").read_text())


def _compare(tmp_path: Path, *runs: Path | str, extra: tuple[str, ...] = ()) -> tuple[subprocess.CompletedProcess, dict]:
    out = tmp_path / "compare.json"
    done = ckesc("compare", *runs, "--json", out, *extra)
    return done, (json.loads(out.read_text()) if out.exists() else {})


def _failed(run: Path) -> set[str]:
    return {r["nodeid"] for r in _doc(run)["results"] if r["outcome"] == "FAIL"}


# ------------------------------------------------------------------------------------------ two runs
def test_a_run_with_a_fault_after_a_clean_one_regressed(runs, tmp_path):
    done, doc = _compare(tmp_path, runs["clean"], runs["late"])
    assert done.returncode == 1, done.stdout + done.stderr
    (pair,) = doc["pairs"]
    assert pair["regressed"] and doc["regressed"]
    failed = _failed(runs["late"])
    assert failed and {r["test"] for r in pair["tests"]["regressed"]} == failed
    assert all(r["before"] == "PASS" and r["after"] == "FAIL" and r["message"] for r in pair["tests"]["regressed"])
    # only the requirements the late answers broke (issue #29): not the others their tests cite (4.4.2-1, 4.4.2-2,
    # 4.4.2-T), whose evidence did not regress; each regressed test names what it broke, as results.json does
    assert {r["requirement"] for r in pair["requirements"]["regressed"]} == {"R2", "4.4.2-4"}
    cited = {rid for r in _doc(runs["late"])["results"] if r["outcome"] == "FAIL" for rid in r["requirements"]}
    assert cited > {"R2", "4.4.2-4"}, "the failing tests cite more than they broke"
    assert all(set(r["broke"]) == {"R2", "4.4.2-4"} for r in pair["tests"]["regressed"])
    assert all(set(r["broken_requirements"]) == {"R2", "4.4.2-4"} for r in _doc(runs["late"])["results"]
               if r["outcome"] == "FAIL")
    assert re.search(r"^    conformance/\S+: PASS -> FAIL \(broke 4\.4\.2-4 R2\): \[4\.4\.2-4 SHALL\]", done.stdout, re.M)
    assert not pair["tests"]["fixed"] and not pair["tests"]["added"] and not pair["tests"]["removed"]
    # the answer-delay margins that shrank, both values as each run recorded them
    shrank = {m["measurement"]: m for m in pair["margins_shrank"]}
    assert any("answer end after the request" in k for k in shrank)
    for m in shrank.values():
        for run, key in ((runs["clean"], "before_ms"), (runs["late"], "after_ms")):
            r = next(r for r in _doc(run)["results"] if r["nodeid"] == m["test"])
            recorded = [x["margin"] for x in r["measured"] if x["name"] == m["name"] and x["unit"] == "ms"]
            assert m[key] in recorded, (m, key, recorded)
        assert m["after_ms"] < m["before_ms"]
    # every limit is judged: the late answer's end crossed its limit (margin below zero)
    assert any(m["after_ms"] < 0 < m["before_ms"] for m in shrank.values()), shrank
    # the DUT side by side: the fault is what differs; the console says it
    (a, b) = doc["runs"]
    assert a["identity"]["firmware date"] == b["identity"]["firmware date"] == "2024-10-11"
    assert b["identity"]["emulator faults"] == FAULT and "emulator faults" not in a["identity"]
    assert re.search(r"^\* emulator faults\s+-\s+answer_late", done.stdout, re.M)
    assert "REGRESSED" in done.stdout.splitlines()[-1]
    assert any(f.startswith("A (") and "SUBSET" in f for f in doc["flags"]), "a subset run is flagged as incomplete"


def test_the_fault_gone_is_fixed_and_exit_0(runs, tmp_path):
    done, doc = _compare(tmp_path, runs["late"], runs["clean"])
    assert done.returncode == 0, done.stdout + done.stderr
    (pair,) = doc["pairs"]
    assert {r["test"] for r in pair["tests"]["fixed"]} == _failed(runs["late"])
    assert "R2" in {r["requirement"] for r in pair["requirements"]["fixed"]}
    assert not pair["tests"]["regressed"] and done.stdout.splitlines()[-1] == "no regression"


def test_runs_from_different_profiles_are_compared_and_flagged(runs, tmp_path):
    done, doc = _compare(tmp_path, runs["clean"], runs["generic"])
    assert done.returncode == 0, done.stdout + done.stderr
    assert any(f.startswith("different DUT profiles") for f in doc["flags"]), doc["flags"]
    assert "! different DUT profiles" in done.stdout
    changed = doc["pairs"][0]["tests"]["changed"]  # the other profile lacks capabilities: those tests are SKIPPED
    assert changed and all((r["before"], r["after"]) == ("PASS", "SKIPPED") for r in changed)


def test_tests_added_and_removed_and_not_run(runs):
    old = _doc(runs["clean"])
    new = copy.deepcopy(old)
    gone = new["results"].pop(0)["nodeid"]  # a test the next suite version no longer has
    moved = new["results"].pop(0)
    new["not_run"].append({"nodeid": moved["nodeid"], "name": moved["name"], "section": moved["section"], "reason": "not run: deselected"})
    extra = {**copy.deepcopy(old["results"][0]), "nodeid": "conformance/test_s4_4_2_msg_control.py::test_new_one"}
    new["results"].append(extra)
    pair = compare.diff(compare.parse_run(old, label="a"), compare.parse_run(new, label="b"))
    assert [r["test"] for r in pair["tests"]["removed"]] == [gone]
    assert [r["test"] for r in pair["tests"]["added"]] == [extra["nodeid"]]
    assert [(r["test"], r["after"]) for r in pair["tests"]["not_run"]] == [(moved["nodeid"], "NOT RUN")]
    assert not pair["regressed"], "a test not run is no regression"


def test_a_margin_shrinking_past_the_threshold_and_the_timing_error(runs):
    old = _doc(runs["clean"])
    new = copy.deepcopy(old)
    r, measured = next((r, m) for r in new["results"] for m in r["measured"]
                       if m["unit"] == "ms" and m["margin"] is not None and m["margin"] > 1)
    before = measured["margin"]
    measured["margin"] = before * 0.95  # 5 % less, still a PASS
    a, b = compare.parse_run(old, label="a"), compare.parse_run(new, label="b")
    assert not compare.diff(a, b)["margins_shrank"], "within the default 10 %"
    (m,) = compare.diff(a, b, threshold=0.04)["margins_shrank"]
    assert (m["before_ms"], m["after_ms"], m["test"]) == (before, before * 0.95, r["nodeid"])
    new["info"]["timing_error_s"] = before * 0.1 / 1000  # the drop is inside what this run's clock can tell
    assert not compare.diff(a, compare.parse_run(new, label="b"), threshold=0.04)["margins_shrank"]


def test_older_records_are_read_from_what_they_recorded(runs):
    """A results.json from before the results carried what they broke and measured as fields (``broken``,
    ``measured``: issue #35) is still compared: its recorded ``broken_requirements`` and its measurements' rendering
    (``measurements``, 6 significant digits) are read, and a run compared with its older self changes nothing."""
    new = _doc(runs["late"])
    old = copy.deepcopy(new)
    for r in old["results"]:
        r.pop("broken"), r.pop("measured")
    a, b = compare.parse_run(old, label="a"), compare.parse_run(new, label="b")
    assert [compare.broken_requirements(r) for r in a.results.values()] == \
        [compare.broken_requirements(r) for r in b.results.values()]
    margins_old, margins_new = compare.timing_margins(a), compare.timing_margins(b)
    assert margins_old and margins_old.keys() == margins_new.keys()
    assert all(abs(margins_old[k]["margin_ms"] - margins_new[k]["margin_ms"]) <= 1e-5 * max(1.0, abs(margins_new[k]["margin_ms"]))
               and margins_old[k]["limit"] == margins_new[k]["limit"] for k in margins_new)
    pair = compare.diff(a, b)
    assert not pair["regressed"] and not pair["margins_shrank"] and not pair["tests"]["changed"]


# ------------------------------------------------------------------------------------------ three runs and the page
@pytest.fixture(scope="module")
def three(runs, tmp_path_factory) -> tuple[subprocess.CompletedProcess, dict, Path]:
    out = tmp_path_factory.mktemp("three")
    done = ckesc("compare", runs["clean"], runs["late"], runs["generic"] / "results.json", "--json", out / "c.json",
                 "--html", out / "c.html")
    return done, json.loads((out / "c.json").read_text()), out / "c.html"


def test_three_runs_make_a_requirement_by_run_matrix(runs, three):
    done, doc, _ = three
    assert done.returncode == 1, "A -> B regressed"
    assert [p["regressed"] for p in doc["pairs"]] == [True, False]
    rows = {row["requirement"]: row["results"] for row in doc["matrix"]}
    assert rows["R2"] == ["PASS", "FAIL", "PASS"]
    want = [compare.requirement_results(compare.read_run(runs[k])) for k in ("clean", "late", "generic")]
    assert rows == {rid: [w.get(rid, "NOT CHECKED") for w in want] for rid in rows}
    assert re.search(r"^  R2\s+READING\s+PASS\s+FAIL\s+PASS", done.stdout, re.M), done.stdout
    trend = {t["measurement"]: t for t in doc["trends"]}
    late = next(t for k, t in trend.items() if "answer end after the request" in k)
    assert len(late["margins_ms"]) == 3 and late["margins_ms"][1] < 0 < late["margins_ms"][0] and late["shrank_at"] == ["B"]


def test_the_page_renders_in_chromium_with_matrix_and_margin_trends(three, tmp_path):
    done, doc, page = three
    text = page.read_text()
    assert "<script" not in text and not re.findall(r'(?:href|src)="[^#"]|url\((?!#)|@import', text), "self-contained"
    dom = _render(page, tmp_path)
    assert "REGRESSED" in dom.find("header").text()
    assert dom.find("section", id="pair-A-B").attrs["data-regressed"] == "true"
    assert dom.find("section", id="pair-B-C").attrs["data-regressed"] == "false"
    assert dom.find("section", id="matrix").find("tr", **{"data-requirement": "R2"}).attrs["data-results"] == "PASS FAIL PASS"
    assert "different DUT profiles" in " ".join(p.text() for p in dom.iter("p", role="alert"))
    assert "diff" in dom.find("tr", **{"data-field": "emulator faults"}).attrs.get("class", "")
    trends = dom.find("section", id="trends")
    rows = {tr.attrs["data-measurement"]: tr for tr in trends.iter("tr") if "data-measurement" in tr.attrs}
    assert set(rows) == {t["measurement"] for t in doc["trends"]}
    for t in doc["trends"]:  # each timing measurement: its margin in each run, and a line of them
        assert rows[t["measurement"]].find("svg"), t["measurement"]
        assert (rows[t["measurement"]].attrs.get("class") == "diff") == bool(t["shrank_at"])
    shot = tmp_path / "compare.png"
    done = _chromium([f"--screenshot={shot}", "--window-size=1200,2400", "--hide-scrollbars", page.resolve().as_uri()],
                     tmp_path / "chromium")
    assert done.returncode == 0 and shot.is_file(), done.stderr[-2000:]
    import matplotlib.image

    pixels = matplotlib.image.imread(shot)
    colours = {tuple((p[:3] * 255).round().astype(int)) for p in pixels[::5, ::5].reshape(-1, pixels.shape[2])}
    assert (0xCF, 0x22, 0x2E) in colours and len(colours) > 50, "the REGRESSED badge on a page, not a blank"


# ------------------------------------------------------------------------------------------ runs that cannot be read
def test_a_run_that_cannot_be_read_is_exit_2_with_one_line(runs, tmp_path):
    (tmp_path / "empty").mkdir()
    (tmp_path / "bad.json").write_text("{not json")
    (tmp_path / "other.json").write_text('{"frames": 3}')
    reports = runs["clean"].parent
    cases = {tmp_path / "nowhere": "no such run", tmp_path / "empty": "no results.json",
             reports: "give one run, e.g. reports/latest", tmp_path / "bad.json": "is not JSON",
             tmp_path / "other.json": "not a results record"}
    for bad, why in cases.items():
        done = ckesc("compare", runs["clean"], bad)
        assert done.returncode == 2, (bad, done.stdout, done.stderr)
        assert len(done.stderr.strip().splitlines()) == 1 and why in done.stderr and str(bad) in done.stderr, done.stderr
        assert done.stdout == ""
    one = ckesc("compare", runs["clean"])
    assert one.returncode == 2 and "two runs or more" in one.stderr
    assert ckesc("compare", runs["clean"], runs["late"], "--margin-threshold", "150").returncode == 2


def test_the_same_run_twice_is_no_regression(runs, tmp_path):
    copied = tmp_path / "copy"
    shutil.copytree(runs["clean"], copied)
    done, doc = _compare(tmp_path, runs["clean"], copied)
    assert done.returncode == 0 and not doc["pairs"][0]["margins_shrank"]
    assert not any(doc["pairs"][0]["tests"][k] for k in ("regressed", "fixed", "changed", "added", "removed", "not_run"))


def test_flags_name_what_differs_and_only_that(runs):
    doc = _doc(runs["clean"])
    whole = copy.deepcopy(doc)
    whole["info"].update(complete=True, incomplete="")
    old = copy.deepcopy(whole)  # a record from before the suite wrote its version, with less in its info
    for key in ("suite_version", "git_revision", "profile"):
        old["info"].pop(key, None)
    runs_ = [compare.parse_run(d, label=n) for n, d in (("old", old), ("whole", whole), ("subset", doc))]
    flags = compare.flags(runs_)
    assert flags == [f"C ({doc['info']['run_id']}) is incomplete: SUBSET - not a conformance result for the whole suite: {doc['info']['incomplete']}; "
                     f"{doc['info']['not_run']} tests not run"], flags
    generic = _doc(runs["generic"])
    assert compare.flags([runs_[1], compare.parse_run({**generic, "info": {**generic["info"], "complete": True}})]) == [
        f"different DUT profiles: A {doc['info']['profile']}, B {generic['info']['profile']}"]


def test_both_kinds_of_comparison_share_one_skeleton():
    """The suite's comparison and the soak's are one skeleton (issue #35 item 6): the letters, the pairs, the flags'
    form, the first and last lines and the page's frame are :mod:`ckesc.reporting.comparing`'s."""
    from ckesc.reporting import comparing, soak_compare

    assert [comparing.letter(i) for i in (0, 1, 25, 26)] == ["A", "B", "Z", "R27"]
    assert comparing.differs("lanes", ["sim", None, "sim"]) == []
    assert comparing.differs("lanes", ["sim", None, "vcan0"], unknown="-") == ["different lanes: A sim, B -, C vcan0"]
    with pytest.raises(ValueError, match="two runs or more"):
        comparing.comparison([1], lambda a, b: {}, dict, [])
    doc = comparing.comparison([1, 2, 3], lambda a, b: {"regressed": b == 3, "to": b}, lambda r: {"n": r}, ["flag"], x=1)
    assert doc == {"runs": [{"letter": "A", "n": 1}, {"letter": "B", "n": 2}, {"letter": "C", "n": 3}], "flags": ["flag"],
                   "pairs": [{"regressed": False, "to": 2}, {"regressed": True, "to": 3}], "x": 1, "regressed": True}
    assert comparing.last_line(doc, lambda p: f"to {p['to']}") == "REGRESSED: B -> C: to 3"
    assert "<p class=banner role=alert>flag</p>" in comparing.page(doc, heading="h", lead="l", body=[])
    for kind in (compare, soak_compare):
        assert kind.comparison is comparing.comparison and kind.page_frame is comparing.page
        assert kind.RunError is comparing.RunError and not hasattr(kind, "_letter")


# ------------------------------------------------------------------------------------------ soak runs (issue #31 item 6)
SOAK = ("--duration", "2m", "--rate", "50", "-q")  # two simulated minutes: two R9 minutes per report, a second each


@pytest.fixture(scope="module")
def soaks(tmp_path_factory) -> dict[str, Path]:
    """A faultless soak, and one whose ESC's clock runs fast from 30 s on (R9's minute means drift: found), run side
    by side."""
    base = tmp_path_factory.mktemp("soaks")
    args = {"clean": (), "drift": ("--emulator-faults", "clock_drift_warm=30")}
    procs = {name: subprocess.Popen([sys.executable, "-m", "ckesc", "soak", "--reports", str(base / name), *SOAK, *extra],
                                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
             for name, extra in args.items()}
    for name, proc in procs.items():
        out, _ = proc.communicate(timeout=600)
        assert proc.returncode == {"clean": 0, "drift": 1}[name], out
    return {name: next((base / name).glob("*-soak")) for name in args}


def test_two_soak_runs_compared_per_watched_property(soaks, tmp_path):
    html = tmp_path / "soak.html"
    done, doc = _compare(tmp_path, soaks["clean"], soaks["drift"], extra=("--html", str(html)))
    assert done.returncode == 1, done.stdout + done.stderr
    assert doc["kind"] == "soak" and doc["regressed"]
    (pair,) = doc["pairs"]
    assert pair["regressed"] == ["report intervals"] and pair["fixed"] == []
    rows = {r["watch"]: r for r in pair["properties"]}
    assert rows["report intervals"]["before"] == 0 and rows["report intervals"]["after"] > 0
    assert all(r["change"] == "same" for w, r in rows.items() if w != "report intervals")
    a, b = doc["runs"]
    # the statement's bound per property, as each run's results.json states it
    assert a["properties"]["resets"]["bound"] == pytest.approx(90.0) and "0 resets in 2 min" in a["properties"]["resets"]["text"]
    # R9 per minute: the faultless ESC on its interval; the drifting one fast, its worst minute off by more
    assert a["r9"]["msg1"]["interval_ms"] == 20 and a["r9"]["msg1"]["worst_error_ms"] == pytest.approx(0, abs=0.01)
    assert b["r9"]["msg1"]["mean_ms"] < 20 and b["r9"]["msg1"]["worst_error_ms"] < -1
    assert a["delays"]["answers"] == b["delays"]["answers"] == 120 and a["delays"]["p99_ms"] is not None
    assert a["resets"]["events"] == b["resets"]["events"] == 0
    assert any("clock_drift_warm" in f for f in doc["flags"])
    assert "A -> B: REGRESSED report intervals" in done.stdout and "report intervals: 0 -> " in done.stdout
    assert "msg1 (every 20 ms): A 20 ms" in done.stdout and "p50 / p90 / p99" in done.stdout
    page = html.read_text()
    assert 'data-watch="report intervals"' in page and "REGRESSED" in page
    back = ckesc("compare", soaks["drift"] / "results.json", soaks["clean"])
    assert back.returncode == 0 and "fixed report intervals" in back.stdout, back.stdout + back.stderr


def test_a_soak_run_with_a_conformance_run_is_exit_2_with_one_line(runs, soaks):
    done = ckesc("compare", runs["clean"], soaks["clean"])
    assert done.returncode == 2 and done.stdout == "", done.stdout + done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "soak run with a conformance run" in done.stderr
    assert f"{soaks['clean']} a soak run" in done.stderr
    # and the library refuses a soak record as a conformance one, saying so
    with pytest.raises(compare.RunError, match="a soak run"):
        compare.read_run(soaks["clean"])
