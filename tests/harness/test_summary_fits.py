"""summary.txt and the console's table never cut a word (issue #38): every section's title whole on its row, every
column head a verdict or an abbreviation the legend says."""

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
