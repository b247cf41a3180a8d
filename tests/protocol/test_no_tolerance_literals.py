"""No tolerance or timing fact retyped outside the catalogue and the judgement module (issue #28: one judgement per
rule). The source of ``ckesc/`` and ``conformance/`` is read with ``ast``; every place that writes

* a small float (below 10 ms: a tolerance's size, ``0.001``, ``0.0005``) or one of the catalogue's timing facts
  (64 ms, 200 ms),
* a ``[2:]`` slice (R9a's gaps skipped by hand),
* a ``1.25 *`` (R9a's restart slack by hand)

must be in :data:`ALLOWED`, each with why it is not a rule's tolerance. A new one fails here: put a tolerance in
``ckesc/protocol/judgements.py`` (or a protocol fact in the catalogue) and call it, or, if it truly is none (a
bench's stated error, the emulator's own timing, float noise), allow it here with the reason.
"""

from __future__ import annotations

import ast
from collections import Counter
from pathlib import Path

from ckesc.bench.profile import DEFAULT_BUS_ERROR_S
from ckesc.protocol import catalogue as cat

ROOT = Path(__file__).resolve().parents[2]
#: where the timing facts and the tolerances are written: the catalogue's timing module and the judgements
TIMING = "ckesc/protocol/catalogue/timing.py"
OWNERS = {TIMING, "ckesc/protocol/judgements.py"}
#: the catalogue's timing facts, which no other module writes as a number
FACTS = {cat.ANSWER_DELAY_MAX_S, cat.COMM_LOSS_TIMEOUT_S}
SMALL_S = 0.01

_NOISE = "float noise in a comparison or a rounding, not a tolerance"
_EMULATOR = "the emulator's own behaviour (what it plays), not a limit any judgement holds a DUT to"
#: (file, literal) -> (how many, why it is not a rule's tolerance)
ALLOWED: dict[tuple[str, str], tuple[int, str]] = {
    ("ckesc/bench/profile.py", "0.002"): (1, "DEFAULT_BUS_ERROR_S: a real bench's timing error, written once "
                                                "(test_the_bench_error_is_written_once), not a rule's tolerance"),
    ("ckesc/bench/dut.py", "0.2"): (1, "OUTPUT_SETTLE_S: a test allowance for a ramping throttle output, not R8's 200 ms"),
    ("ckesc/bench/link.py", "0.0025"): (1, "throttle_stream's default period: the harness's command rate"),
    ("ckesc/emulator/model.py", "0.007"): (1, _EMULATOR),
    ("ckesc/emulator/esc_output.py", "0.001"): (1, _EMULATOR),
    ("ckesc/emulator/realtime.py", "0.0005"): (1, _EMULATOR),
    ("ckesc/emulator/realtime.py", "0.2"): (1, "a poll timeout of the real-time emulator's loop, not R8's 200 ms"),
    ("ckesc/emulator/realtime_timing.py", "1e-06"): (1, _EMULATOR),
    ("ckesc/emulator/realtime_timing.py", "0.001"): (1, _EMULATOR),
    ("ckesc/emulator/esc_telemetry.py", "0.003"): (1, "the report_interval_wrong fault's wrong unit (a fault the suite must find)"),
    ("ckesc/emulator/variants.py", "0.003"): (1, "the jitter a conforming variant may play (declared as its profile's jitter_s)"),
    ("ckesc/emulator/variants.py", "0.0002"): (1, _EMULATOR),
    ("ckesc/emulator/variants.py", "0.0005"): (1, _EMULATOR),
    ("ckesc/emulator/hub_can.py", "0.0005"): (1, "FOREIGN_FRAME_S: how long a node at another bit rate garbles the bus per frame (the fault played), not a limit"),
    ("ckesc/emulator/hub_can.py", "0.00103"): (1, "FOREIGN_PERIOD_S: how often that node sends, on its own clock (the fault played), not a limit"),
    ("ckesc/evidence/checklog.py", "0.001"): (1, "USB_ADAPTER_ERROR_S: a capturing adapter's stated error (a bench's error)"),
    ("ckesc/evidence/findings.py", "0.0005"): (1, "a histogram bin's width in the summary, not a limit"),
    ("ckesc/evidence/findings.py", "1e-06"): (1, _NOISE),
    ("ckesc/evidence/rules.py", "1e-09"): (1, _NOISE),
    ("ckesc/evidence/tracker.py", "1e-09"): (1, _NOISE),
    ("ckesc/explore/actions.py", "0.006"): (1, "how long the explorer reads past the 64 ms bound for an answer (a read window)"),
    ("ckesc/reporting/compare.py", "1e-06"): (1, _NOISE),
    ("ckesc/soak/batch.py", "0.2"): (1, "POLL_S: how often a soak batch reads its benches' status files, not R8's 200 ms"),
    ("ckesc/soak/monitor.py", "0.0001"): (1, "LAG_BIN_S: a histogram bin's width for the bench's stamp lag, not a limit"),
    ("ckesc/soak/runner.py", "0.0001"): (1, "LATENESS_BIN_S: a histogram bin's width for the host's send lateness, not a limit"),
    ("ckesc/rigs/rig.py", "[2:]"): (2, "a rig file's key path without its first two parts, not report gaps"),
    ("conformance/answers.py", "1e-12"): (1, _NOISE),
    ("conformance/test_s4_4_3_get_esc_id.py", "0.007"): (1, "PHASE_STEP_S: how a test moves its request across the slots"),
    ("conformance/throttle.py", "0.0025"): (1, "STREAM_PERIOD_S: the harness's command rate"),
}


def _found(path: Path) -> list[str]:
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Constant) and isinstance(node.value, float) and not isinstance(node.value, bool):
            if 0 < abs(node.value) < SMALL_S or node.value in FACTS:
                out.append(repr(node.value))
        elif isinstance(node, ast.Slice) and node.upper is None and node.step is None \
                and isinstance(node.lower, ast.Constant) and node.lower.value == 2:
            out.append("[2:]")
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult) \
                and any(isinstance(x, ast.Constant) and x.value == 1.25 for x in (node.left, node.right)):
            out.append("1.25 *")
    return out


def _scan() -> Counter:
    found: Counter = Counter()
    for base in ("ckesc", "conformance"):
        for path in sorted((ROOT / base).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel not in OWNERS:
                found.update((rel, lit) for lit in _found(path))
    return found


def test_no_tolerance_literal_outside_the_catalogue_and_the_judgements():
    found = _scan()
    allowed = Counter({k: n for k, (n, _) in ALLOWED.items()})
    new = found - allowed
    assert not new, ("tolerance or timing-fact literals outside ckesc/protocol/catalogue/timing.py and judgements.py "
                     f"(put them there and call them, or allow them in this test with why): {dict(new)}")
    gone = allowed - found
    assert not gone, f"allowed literals no longer there (take them out of ALLOWED): {dict(gone)}"


#: where a real bench's timing error is written (issue #28): its one owner, with its reason
BENCH_ERROR_OWNER = "ckesc/bench/profile.py"
#: keyword arguments that state a bench's error: the project's tests pass the constant, not its value
ERROR_KEYWORDS = {"timing_error", "host_send_error", "error_s"}


def _bench_errors(path: Path, rel: str) -> list[int]:
    """Lines of ``path`` that write the bench's error as a number: in the package and the suite, its value anywhere
    (the catalogue's 2 ms are protocol facts: the R2 slot, the report interval's unit); in the project's tests, a
    number passed as a bench's error (``timing_error=0.002``: the rest of their 2 ms are the R2 slot's)."""
    value = DEFAULT_BUS_ERROR_S
    lines = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if rel.startswith("tests/"):
            if isinstance(node, ast.keyword) and node.arg in ERROR_KEYWORDS and isinstance(node.value, ast.Constant) \
                    and node.value.value == value:
                lines.append(node.value.lineno)
        elif isinstance(node, ast.Constant) and isinstance(node.value, float) and node.value == value:
            lines.append(node.lineno)
    return sorted(lines)


def test_the_bench_error_is_written_once():
    """A real bench's 2 ms timing error (the default on a real bus, the real-time lane's least, the host's send error)
    is :data:`ckesc.bench.profile.DEFAULT_BUS_ERROR_S`, and everything else imports it: a second copy fails here."""
    found = {}
    for base in ("ckesc", "conformance", "tests"):
        for path in sorted((ROOT / base).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            if rel != TIMING and (lines := _bench_errors(path, rel)):
                found[rel] = lines
    assert len(found.pop(BENCH_ERROR_OWNER, [])) == 1, f"{BENCH_ERROR_OWNER} no longer writes DEFAULT_BUS_ERROR_S once"
    assert not found, (f"the bench's error {DEFAULT_BUS_ERROR_S} written again (import DEFAULT_BUS_ERROR_S from "
                       f"ckesc.bench.profile, or name another figure with its reason): {found}")


def test_the_scan_sees_what_it_counts(tmp_path):
    """The scan itself: each kind it counts is seen (a scan that sees nothing would pass anything)."""
    src = tmp_path / "x.py"
    src.write_text("a = b <= 0.001\nc = gaps[2:]\nd = 1.25 * x\ne = t > 0.064\nf = 0.5\ng = s[1:]\n")
    assert sorted(_found(src)) == sorted(["0.001", "[2:]", "1.25 *", "0.064"])
    assert _bench_errors(src, "ckesc/x.py") == [] and _bench_errors(src, "tests/x.py") == []
    src.write_text("a = 0.002\nlane = Lane(timing_error=0.002)\nslot = n * 0.002\n")
    assert _bench_errors(src, "ckesc/x.py") == [1, 2, 3] and _bench_errors(src, "tests/x.py") == [2]
