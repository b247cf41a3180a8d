"""The HTML kit of the reports (report.html, compare.html, batch.html): escaping, verdict badges, anchors,
the shared stylesheet and matplotlib figures inlined as SVG. Self-contained pages: inline CSS and SVG only,
no script, no external URL."""

from __future__ import annotations

import html
import io
from typing import Any

#: a badge's colour per verdict, status and banner word
COLOURS = {"PASS": "#1a7f37", "FAIL": "#cf222e", "ERROR": "#8250df", "INCONCLUSIVE": "#bf8700", "OBSERVED": "#0969da",
           "SKIPPED": "#6e7781", "NOT CHECKED": "#6e7781",
           "ABORTED": "#cf222e", "INTERRUPTED": "#bf8700", "SUBSET": "#6e7781", "INCOMPLETE": "#bf8700",
           "REGRESSED": "#cf222e"}


def e(value: Any) -> str:
    """``value`` as HTML text (attribute-safe)."""
    return html.escape(str(value), quote=True)


def badge(verdict: str) -> str:
    """A verdict (or status) as a coloured badge."""
    return f'<span class="v v-{verdict.replace(" ", "-")}">{e(verdict)}</span>'


def anchor(nodeid: str) -> str:
    """A test id as an HTML id (``#t-<anchor>``)."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in nodeid)


def figure(fid: str, title: str, svg: str, caption: str) -> str:
    """A figure with its title and caption (``caption`` is HTML)."""
    return f'<figure id="{fid}"><figcaption><b>{e(title)}.</b> {caption}</figcaption>{svg}</figure>'


def svg(fig) -> str:
    """A matplotlib figure as inline SVG (deterministic: no date, a fixed hash salt)."""
    buf = io.StringIO()
    fig.savefig(buf, format="svg", bbox_inches="tight", metadata={"Date": None, "Creator": None})
    text = buf.getvalue()
    return text[text.index("<svg"):]


def new_figure(width: float, height: float):
    """A matplotlib figure (inches), text kept as text in its SVG; matplotlib is imported only here."""
    import matplotlib

    matplotlib.rcParams.update({"svg.fonttype": "none", "svg.hashsalt": "ckesc", "font.size": 10})
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height))


CSS = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:1.5rem auto;max-width:72rem;padding:0 1rem;color:#1f2328}
h1{font-size:1.6rem;margin:0}h2{font-size:1.25rem;border-bottom:1px solid #d0d7de;padding-bottom:.2rem;margin-top:2rem}
h3{font-size:1rem;margin:.2rem 0}.run{color:#57606a}.banner{background:#fff8c5;border:1px solid #bf8700;padding:.5rem .8rem;font-weight:600}
table{border-collapse:collapse;margin:.4rem 0}th,td{border:1px solid #d0d7de;padding:.2rem .45rem;vertical-align:top;text-align:left}
th{background:#f6f8fa}.kv th{width:12rem}
.matrix td.n{text-align:right;font-variant-numeric:tabular-nums}.matrix td.zero{color:#afb8c1}
.matrix .total td{font-weight:600;border-top:2px solid #57606a}
.c-PASS{background:#dafbe1}.c-FAIL{background:#ffebe9;font-weight:700}.c-ERROR{background:#fbefff;font-weight:700}
.c-INCONCLUSIVE{background:#fff8c5}.c-OBSERVED{background:#ddf4ff}.c-SKIPPED{background:#f6f8fa}
.v{display:inline-block;padding:0 .35rem;border-radius:.6rem;color:#fff;font-size:.75rem;font-weight:600;white-space:nowrap}
""" + "".join(f".v-{k.replace(' ', '-')}{{background:{c}}}" for k, c in COLOURS.items()) + """
article.cause{border-left:4px solid #cf222e;padding:.2rem .8rem;margin:.8rem 0;background:#fffafa}
article.cause[data-strength=READING]{border-left-color:#bf8700}.count{color:#57606a;font-weight:400}
summary{cursor:pointer;color:#0969da}
article.fail{border-left:4px solid #cf222e;padding:.2rem .8rem;margin:.8rem 0;background:#fffafa}
pre{white-space:pre-wrap;font-size:.8rem;background:#f6f8fa;padding:.4rem;max-height:14rem;overflow:auto}
.meas{font-size:.8rem}.obs{font-size:.8rem;margin:.2rem 0}.traces{font-size:.8rem;margin:.2rem 0}.msg{color:#cf222e;font-size:.8rem}
.reqs q{quotes:none;font-style:italic}.note{color:#57606a;font-size:.8rem}.tests{margin:.2rem 0;padding-left:1rem;font-size:.8rem}
figure{margin:1rem 0;break-inside:avoid}figure svg{width:100%;height:auto}figcaption{font-size:.85rem;color:#57606a}
.tests td{font-size:.85rem}
@media print{body{max-width:none;margin:0;font-size:11px}a{color:inherit;text-decoration:none}pre{max-height:none}
 section{break-inside:auto}tr,article{break-inside:avoid}h2{break-after:avoid}}
"""
