"""Failures grouped by cause (issue #12, item 1): one broken bus rule (R9, the emulator's
report_interval_wrong) fails nearly every test; with a second fault (answer_late) at once, the run's
distinct problems must come first - one group each, SHALL before READING, the tests of each listed
under it - in report.html (rendered in headless Chromium), summary.txt and the console, and
``ckesc report`` must rebuild them from results.json, older records without ``bus_causes`` included."""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from ckesc.reporting.causes import groups, summary_lines
from ckesc.reporting.report import summary_text
from ckesc.reporting.results import Result

pytestmark = pytest.mark.xdist_group(__name__)  # its module-scoped runs are made once: its tests share one worker

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
FAULTS = "report_interval_wrong,answer_late"


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> tuple[Path, str]:
    base = tmp_path_factory.mktemp("causes")
    done = subprocess.run([sys.executable, "-m", "ckesc", "run", "-q", "--reports", str(base), "--emulator-faults", FAULTS],
                          capture_output=True, text=True, timeout=900)
    out = next(p for p in base.iterdir() if p.is_dir() and not p.is_symlink())
    return out, done.stdout


def _doc(out: Path) -> dict:
    return json.loads((out / "results.json").read_text())


def test_one_broken_rule_is_one_group_and_the_other_faults_are_seen(run):
    out, _ = run
    results = _doc(out)["results"]
    failed = [r for r in results if r["outcome"] == "FAIL"]
    assert len(failed) > 250, "report_interval_wrong fails nearly every test"
    gs = groups(results)
    first = gs[0]
    assert first.title.startswith("R9") and "MSG1 of node 1 every 30 ms, not 20 ms" in first.title, first.title
    assert len(first.tests) > 250 and len(set(first.tests)) == len(first.tests)
    assert first.first.count("\n    (") >= 1, "its first occurrence quotes the frames"
    assert first.traces, "and links the trace of the test it was first seen in"
    # about 30 causes for ~330 failing tests (the robustness section's R17 and R18 modules add their own few)
    assert len(gs) < 35, f"a few distinct problems, not one per test: {[g.title for g in gs]}"
    late = [g for g in gs if g.title.startswith("4.4.2-4") or g.title.startswith("4.4.3-4")]
    assert late and all(g.strength == "SHALL" and "answer delay = 80." in g.title for g in late)
    assert {t for g in late for t in g.tests} >= {r["nodeid"] for r in failed if "answer delay" in r["message"]}
    strengths = [g.strength for g in gs]
    assert strengths == sorted(strengths, key=("SHALL", "READING").index), "SHALL before READING"
    recorded = [c for r in failed for c in r["bus_causes"]]
    assert recorded and all({"key", "what", "rules", "node", "first"} <= set(c) for c in recorded)


def test_summary_and_console_group_the_same_way(run):
    out, stdout = run
    summary = (out / "summary.txt").read_text()
    lines = summary_lines(_doc(out)["results"])
    assert lines[0].startswith("failures by cause: ") and "\n".join(lines) in summary
    assert re.search(r"^  1\. \[FAIL SHALL\] R9 .*MSG1 of node 1 every 30 ms, not 20 ms - in \d{3} tests$", summary, re.M)
    assert "\n".join(lines[:4]) in stdout, "the console's closing summary shows the groups too"
    assert len(summary.splitlines()) < 120, "no line per failing test"


def test_report_html_leads_with_the_groups(run, tmp_path):
    out, _ = run
    if CHROMIUM is None:
        pytest.skip("headless Chromium is not installed (Debian: apt-get install chromium)")
    done = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                           f"--user-data-dir={tmp_path / 'chromium'}", "--dump-dom", (out / "report.html").resolve().as_uri()],
                          capture_output=True, text=True, timeout=180)
    dom = done.stdout
    assert done.returncode == 0 and "<html" in dom, done.stderr[-2000:]
    assert dom.index('id="causes"') < dom.index('id="dut"') < dom.index('id="failures"'), "the groups come first"
    articles = re.findall(r'<article class="cause" id="cause-(\d+)" data-tests="(\d+)".*?</article>', dom, re.S)
    gs = groups(_doc(out)["results"])
    assert len(articles) == len(gs)
    for (n, count), body in zip(articles, re.findall(r'<article class="cause".*?</article>', dom, re.S)):
        g = gs[int(n) - 1]
        assert int(count) == len(g.tests)
        listed = re.search(r"<details><summary>.*?</summary><ul class=\"tests\">(.*?)</ul></details>", body, re.S)
        assert listed and listed.group(1).count("<li>") == len(g.tests), "the tests collapsed under the group"
        assert "in " + str(len(g.tests)) + " test" in body


def test_ckesc_report_rebuilds_the_groups_from_older_records(run, tmp_path):
    """A record from before the causes (``bus_causes``) and what a test broke (``broken``) were recorded: its messages
    are not read back for rules and strengths (issue #35); each failure is grouped by its message's first line, so
    every failing test is still in a group, and the test's own failures keep their groups."""
    out, _ = run
    doc = _doc(out)
    for r in doc["results"]:
        r.pop("bus_causes", None), r.pop("broken", None)
    (tmp_path / "results.json").write_text(json.dumps(doc))
    old, new = groups(doc["results"]), groups(_doc(out)["results"])
    failing = {r["nodeid"] for r in doc["results"] if r["outcome"] in ("FAIL", "ERROR")}
    assert {t for g in old for t in g.tests} == failing == {t for g in new for t in g.tests if t in failing}
    own = [g for g in new if not g.key.startswith("bus|")]
    assert own and all(any(set(g.tests) <= set(o.tests) for o in old) for g in own)
    done = subprocess.run([sys.executable, "-m", "ckesc", "report", str(tmp_path)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0
    assert 'id="cause-1"' in (tmp_path / "report.html").read_text()


def _record(nodeid: str, outcome: str, message: str, broken: list | None = None) -> dict:
    return {"nodeid": nodeid, "name": nodeid.split("::")[-1], "section": "4.4.3", "requirements": ["4.4.3-1"],
            "strength": "SHALL", "outcome": outcome, "message": message, "broken": broken or []}


def test_a_causes_heading_is_its_first_tests_own_text(tmp_path):
    """Issue #29: grouping made "127.0.0.1:40594" "127.0.1:40594" and "failed (3)" "failed" in summary.txt and
    report.html's headings. The numbers are left out of the key that groups (the second of each pair joins the
    first's group), never out of the heading: the first test's own line."""
    mod = "conformance/test_s4_4_3_get_esc_id.py"
    refused = "OSError: socketcand at 127.0.0.1:40594 refused the connection"
    power = "RuntimeError: power command ['sh', '-c', 'exit 3'] failed (3)"
    results = [_record(f"{mod}::test_a", "ERROR", refused), _record(f"{mod}::test_b", "ERROR", power),
               _record(f"{mod}::test_c", "ERROR", refused.replace("40594", "40611")),
               _record(f"{mod}::test_d", "ERROR", power.replace("3", "4")),
               _record(f"{mod}::test_e", "FAIL", "[4.4.3-1 SHALL] node 1.0.0.2 answered 3.000 ms late (limit <= 2 ms)",
                       [{"requirements": ["4.4.3-1"], "strength": "SHALL",
                         "text": "node 1.0.0.2 answered 3.000 ms late (limit <= 2 ms)"}])]
    gs = groups(results)
    assert [(g.what, g.tests) for g in gs] == [
        ("node 1.0.0.2 answered 3.000 ms late (limit <= 2 ms)", [f"{mod}::test_e"]),
        (refused, [f"{mod}::test_a", f"{mod}::test_c"]), (power, [f"{mod}::test_b", f"{mod}::test_d"])]
    summary = summary_text([Result.from_json(r) for r in results], {})
    for g in gs:
        assert f"{g.what} - in {len(g.tests)} test" in summary
    (tmp_path / "results.json").write_text(json.dumps({"info": {}, "results": results}))
    done = subprocess.run([sys.executable, "-m", "ckesc", "report", str(tmp_path)], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    headings = re.findall(r'<article class="cause".*?<h3>(.*?)</h3>', (tmp_path / "report.html").read_text(), re.S)
    assert len(headings) == 3
    for g, heading in zip(gs, headings):
        assert g.what in html.unescape(heading), heading
