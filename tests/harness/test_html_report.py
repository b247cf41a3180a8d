"""The HTML conformance report, built from real short runs against the emulator (one faultless, one
with a fault so there is a FAIL), rendered in headless Chromium and checked for what it shows."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from collections import Counter
from html.parser import HTMLParser
from pathlib import Path

import pytest

from ckesc.bench.station import MULTI_NODES
from ckesc.protocol import catalogue as cat
from ckesc.reporting.html_report import build

pytestmark = pytest.mark.xdist_group(__name__)  # its module-scoped runs are made once: its tests share one worker

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: a few sections with every plot's evidence: answer delays of several nodes (4.4.2, 4.4.3), report
#: intervals at several targets (4.4.22), and the comm-loss timelines (R8)
SELECTION = "test_s4_4_2_msg_control or test_s4_4_3_get_esc_id or comm_loss_flag_sets_after or test_s4_4_22"
FAULT = "answer_late"  # MSG Control and GET_ESC_ID answered 80 ms after the request: over the 64 ms limit


def _run(reports: Path, *args: str) -> Path:
    subprocess.run([sys.executable, "-m", "ckesc", "run", "-q", "--reports", str(reports), *args, "--", "-k", SELECTION],
                   capture_output=True, text=True, timeout=600)
    runs = [p for p in reports.iterdir() if p.is_dir() and not p.is_symlink()]
    assert len(runs) == 1, f"one run directory expected in {reports}: {runs}"
    return runs[0]


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    base = tmp_path_factory.mktemp("html")
    return {"clean": _run(base / "clean"), "fault": _run(base / "fault", "--emulator-faults", FAULT)}


# ------------------------------------------------------------------------------------------ a small DOM
class Node:
    def __init__(self, tag: str, attrs: dict[str, str], parent: Node | None) -> None:
        self.tag, self.attrs, self.parent = tag, attrs, parent
        self.children: list[Node] = []
        self.texts: list[str] = []

    def text(self) -> str:
        return " ".join([*self.texts, *(c.text() for c in self.children)]).strip()

    def iter(self, tag: str | None = None, **attrs: str):
        if (tag is None or self.tag == tag) and all(self.attrs.get(k.rstrip("_")) == v for k, v in attrs.items()):
            yield self
        for c in self.children:
            yield from c.iter(tag, **attrs)

    def find(self, tag: str | None = None, **attrs: str) -> Node:
        found = next(self.iter(tag, **attrs), None)
        assert found is not None, f"no <{tag} {attrs}> in <{self.tag} {self.attrs}>"
        return found


class _Dom(HTMLParser):
    VOID = {"meta", "br", "img", "input", "link", "hr", "col", "area", "base", "source", "wbr"}

    def __init__(self) -> None:
        super().__init__()
        self.root = self.cur = Node("#root", {}, None)

    def handle_starttag(self, tag, attrs):
        node = Node(tag, {k: v or "" for k, v in attrs}, self.cur)
        self.cur.children.append(node)
        if tag not in self.VOID:
            self.cur = node

    def handle_startendtag(self, tag, attrs):
        self.cur.children.append(Node(tag, {k: v or "" for k, v in attrs}, self.cur))

    def handle_endtag(self, tag):
        node = self.cur
        while node is not None and node.tag != tag:
            node = node.parent
        if node is not None and node.parent is not None:
            self.cur = node.parent

    def handle_data(self, data):
        if data.strip():
            self.cur.texts.append(data.strip())


def _chromium(args: list[str], profile: Path) -> subprocess.CompletedProcess:
    if CHROMIUM is None:
        pytest.skip("headless Chromium is not installed (Debian: apt-get install chromium)")
    return subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
                           f"--user-data-dir={profile}", *args], capture_output=True, text=True, timeout=180)


def _render(report: Path, tmp_path: Path) -> Node:
    """The report's DOM as headless Chromium built it."""
    done = _chromium(["--dump-dom", report.resolve().as_uri()], tmp_path / "chromium")
    assert done.returncode == 0 and "<html" in done.stdout, done.stderr[-2000:]
    dom = _Dom()
    dom.feed(done.stdout)
    return dom.root


@pytest.fixture(scope="module")
def doms(runs, tmp_path_factory) -> dict[str, Node]:
    """Each run's report as Chromium shows it (rendered once per module)."""
    tmp = tmp_path_factory.mktemp("chromium")
    return {name: _render(out / "report.html", tmp) for name, out in runs.items()}


def _results(out: Path) -> list[dict]:
    return json.loads((out / "results.json").read_text())["results"]


# ------------------------------------------------------------------------------------------ tests
def test_the_section_matrix_counts_what_the_run_recorded(runs, doms):
    for name, out in runs.items():
        dom = doms[name]
        expected = Counter((r["section"], r["outcome"]) for r in _results(out))
        matrix = dom.find("table", class_="matrix")
        rows = {tr.attrs["data-section"]: tr for tr in matrix.iter("tr") if "data-section" in tr.attrs}
        assert set(rows) == {s for s, _ in expected} | {"all"}
        for section, tr in rows.items():
            for cell in tr.iter("td"):
                if "data-verdict" in cell.attrs:
                    want = (sum(n for (s, v), n in expected.items() if v == cell.attrs["data-verdict"]) if section == "all"
                            else expected[(section, cell.attrs["data-verdict"])])
                    assert int(cell.text()) == want, (section, cell.attrs["data-verdict"])


def test_the_dut_identity_is_shown(runs, doms):
    out = runs["clean"]
    info = json.loads((out / "results.json").read_text())["info"]
    table = {tr.find("th").text(): tr.find("td").text() for tr in doms["clean"].find("section", id="dut").iter("tr")}
    esc = info["esc_information"]
    assert table["node id"] == str(info["node_id"]) and table["profile"] == info["profile"] and table["lane"] == "simulated"
    assert table["bit rate"] == f"{info['bitrate']} bit/s"
    assert table["firmware date"] == f"20{esc['firmware_year']:02d}-{esc['firmware_month']:02d}-{esc['firmware_day']:02d}"
    assert table["protocol version"] == str(esc["protocol_version"])


def test_a_failing_requirement_is_listed_with_its_evidence(runs, doms):
    out = runs["fault"]
    failed = [r for r in _results(out) if r["outcome"] == "FAIL"]
    assert failed, f"the {FAULT} fault must fail a test"
    dom = doms["fault"]
    section = dom.find("section", id="failures")
    articles = {a.attrs["data-nodeid"]: a for a in section.iter("article")}
    assert {r["nodeid"] for r in failed} <= set(articles)
    for r in failed:
        text = articles[r["nodeid"]].text()
        props = r["properties"]
        broke = [k.rsplit(".", 1)[0] for k, v in props.items() if k.startswith("measurement.") and k.endswith(".verdict") and v == "FAIL"]
        assert broke, f"{r['nodeid']}: the measurement that failed is recorded"
        for m in broke:  # what was measured, the value, the limit it broke, the margin
            assert all(props[f"{m}.{key}"] in text for key in ("name", "value", "limit", "margin")), (m, text)
        assert "R2" in text and "FAIL" in text, "the requirement and the verdict"
        assert all(Path(t).name in text for t in r["traces"].values()), "the test's traces are linked"
    requirement = dom.find("tr", id="req-R2")
    assert requirement.attrs["data-result"] == "FAIL"
    clean = doms["clean"]
    assert clean.find("tr", id="req-R2").attrs["data-result"] == "PASS"
    assert "No test failed" in clean.find("section", id="failures").text()


def test_the_plots_are_svg_with_their_limits(doms):
    for name, dom in doms.items():
        answer = dom.find("figure", id="answer-delay")
        svg = answer.find("svg")
        assert svg.find(id="answer-delay-limit").find("path"), "the 64 ms limit line"
        assert f"limit {cat.ANSWER_DELAY_MAX_S * 1000:g} ms" in answer.text()
        words = answer.text().split()
        nodes = {int(b) for a, b in zip(words, words[1:]) if a == "node" and b.isdigit()}
        assert nodes == {1, *MULTI_NODES}, "one column per node that answered (the multi-ESC bench included)"
        ids = {n.attrs.get("id", "") for n in svg.iter()}
        assert {f"slot-node-{n}" for n in nodes} <= ids, "each node's own R2 slot is drawn"
        late = {i for i in ids if i.startswith("late-node-")}
        labels = [float(a) for a, b in zip(words, words[1:]) if b == "ms" and re.fullmatch(r"\d+\.\d", a)]
        if name == "fault":  # 80 ms answers: over the slot and the 64 ms bound, red and labelled per node
            assert {i.split("-")[2] for i in late} == {str(n) for n in nodes}, late
            assert len(labels) == len(nodes) and all(x > cat.ANSWER_DELAY_MAX_S * 1000 for x in labels), labels
        else:
            assert not late and not labels, (late, labels)
        assert "get_esc_id" in answer.text() and "set_freq" in answer.text(), "a legend entry per service"
        intervals = dom.find("figure", id="report-intervals")
        targets = {n.attrs["id"] for n in intervals.find("svg").iter() if n.attrs.get("id", "").startswith("target-")}
        assert {"target-msg1-20ms", "target-msg2-100ms", "target-msg3-500ms"} <= targets, targets  # the defaults (R9)
        bands = {n.attrs["id"] for n in intervals.find("svg").iter() if n.attrs.get("id", "").startswith("tolerance-")}
        assert {t.replace("target-", "tolerance-") for t in targets} == bands, "each panel has its tolerance band"
        caption = intervals.find("figcaption").text()
        assert "The intervals the bus rules judged" in caption, caption  # what the plot draws: evidence/tracker.py
        assert "interval - target (ms)" in intervals.text(), "deviation from the target, linear"
        comm = dom.find("figure", id="comm-loss")
        assert len([n for n in comm.iter() if n.attrs.get("id") == "comm-loss-timeout"]) == 3, "one timeline per format"


def test_the_plots_are_full_width_and_legible(runs):
    """At 100 % zoom in a 1200 px window each plot spans the page and no text is under 10 px."""
    page = (runs["fault"] / "report.html").read_text()
    width = 1152 - 32  # body: max-width 72rem, padding 1rem each side
    assert "figure svg{width:100%;height:auto}" in page
    for svg in re.findall(r"<svg .*?</svg>", page, re.S):
        points = float(re.search(r'viewBox="0 0 ([\d.]+) ', svg).group(1))
        sizes = [float(x) for x in re.findall(r"font-size: ([\d.]+)px", svg)]
        assert sizes and min(sizes) * width / points >= 10, (min(sizes), points)


def test_the_report_is_self_contained_and_renders(runs, tmp_path):
    page = (runs["fault"] / "report.html").read_text()
    assert "<script" not in page and "src=" not in page
    external = re.findall(r'(?:href|src)="(?!#|traces/|data:image/png;base64,)[^"]*"|url\((?!#)[^)]*\)|@import', page)
    assert not external, f"only the traces, in-page anchors and inlined images (dense scatter plots): {external[:5]}"
    shot = tmp_path / "report.png"
    done = _chromium([f"--screenshot={shot}", "--window-size=1200,2400", "--hide-scrollbars",
                      (runs["fault"] / "report.html").resolve().as_uri()], tmp_path / "chromium")
    assert done.returncode == 0 and shot.is_file(), done.stderr[-2000:]
    import matplotlib.image

    pixels = matplotlib.image.imread(shot)
    assert pixels.shape[:2] == (2400, 1200)
    colours = {tuple((p[:3] * 255).round().astype(int)) for p in pixels[::7, ::7].reshape(-1, pixels.shape[2])}
    assert (0xCF, 0x22, 0x2E) in colours, "the FAIL badges and limit lines are drawn"
    assert len(colours) > 50, "a page, not a blank"


def test_ckesc_report_rebuilds_it(runs, tmp_path):
    copy = tmp_path / "copied-run"
    shutil.copytree(runs["clean"], copy)
    (copy / "report.html").unlink()
    done = subprocess.run([sys.executable, "-m", "ckesc", "report", str(copy)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and done.stdout.strip() == str(copy / "report.html")
    assert (copy / "report.html").read_text() == build(runs["clean"]).read_text().replace(runs["clean"].name, copy.name)
    bad = subprocess.run([sys.executable, "-m", "ckesc", "report", str(tmp_path / "nowhere")], capture_output=True, text=True)
    assert bad.returncode == 2 and "no results.json" in bad.stderr
