"""Output that fits (issue #38): summary.txt and the console's table never cut a word (every section's title whole on
its row, every column head a verdict or an abbreviation the legend says); the HTML report says of every red mark
whether a test FAILed on it, and why it broke no rule where none did."""

from __future__ import annotations

from ckesc.protocol.requirements import SECTION_TITLES, VERDICT_SHORT, VERDICTS, Verdict
from ckesc.reporting.report import summary_text
from ckesc.reporting.results import Result


def _results() -> list[Result]:
    return [Result(nodeid=f"conformance/x.py::t{i}", name=f"t{i}", section=section, requirements=[], strength="SHALL",
                   outcome=VERDICTS[i % len(VERDICTS)])
            for i, section in enumerate(SECTION_TITLES)]


def test_every_section_title_is_whole_on_its_row():
    lines = summary_text(_results(), {}).splitlines()
    for section, title in SECTION_TITLES.items():
        row = next(line for line in lines if line.split(" ", 1)[0] == section)
        assert row.endswith(f"  {title}"), (section, row)


def test_every_column_head_is_a_verdict_or_said_in_the_legend():
    lines = summary_text(_results(), {}).splitlines()
    heads = lines[0].split()
    assert heads[0] == "section" and heads[-1] == "title"
    assert heads[1:-1] == [VERDICT_SHORT[v] for v in VERDICTS]
    legend = next(line for line in lines if line.startswith("verdicts: "))
    for v in VERDICTS:
        assert VERDICT_SHORT[v] == v.value or f"{VERDICT_SHORT[v]} {v.value}" in legend, (v, legend)
    assert VERDICT_SHORT[Verdict.INCONCLUSIVE] != Verdict.INCONCLUSIVE.value  # the legend is needed: it says one


def test_the_counts_stand_under_their_heads():
    lines = summary_text(_results(), {}).splitlines()
    head = lines[0]
    total = next(line for line in lines if line.startswith("all "))
    for v in VERDICTS:  # each count right-aligned under its column's head
        end = head.index(VERDICT_SHORT[v]) + len(VERDICT_SHORT[v])
        assert total[end - 1].isdigit() and (end == len(total) or total[end] == " "), (v, head, total)


def _with_interval(outcome: Verdict, bus_rules: list[str]) -> Result:
    return Result(nodeid="conformance/x.py::t", name="t", section="4.4.4", requirements=["R9"], strength="SHALL",
                  outcome=outcome, bus_rules=bus_rules,
                  evidence={"intervals": {"msg1": {"0.02": [0.02, 0.0207, 0.02]}},  # one gap 0.7 ms long: red
                            "answers": {"1": {"set_freq": [0.0051]}}})  # node 1's slot ends at 4 ms: red


def test_every_red_mark_of_a_passing_run_is_said_to_break_no_rule():
    from ckesc.reporting.html_report import _plots

    page = _plots([_with_interval(Verdict.PASS, [])], {"interval_tolerance_ms": 0.5})
    assert "1 interval(s) outside it" in page and "No test FAILed on R9: a red mark here broke no rule" in page
    assert "1 answer(s) outside a limit" in page and "No test FAILed on R2 / 4.4.2-4 / 4.4.3-4" in page
    page = _plots([_with_interval(Verdict.FAIL, ["R9"])], {"interval_tolerance_ms": 0.5})
    assert "1 test(s) FAILed on R9 (their rows below say which intervals)" in page
