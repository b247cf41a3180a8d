"""The judgement of each timed or matched rule (ckesc.protocol.judgements), at and around its limits."""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol import judgements as J
from ckesc.protocol.frame import Decoder, encode
from ckesc.protocol.ids import Kind

MS = 0.001
EPS = 1e-6  # well outside float noise, well inside any tolerance


# ------------------------------------------------------------------------------------------ R9
def _grid(interval: float, n: int, first: float = 0.0) -> list[float]:
    return [first + k * interval for k in range(n)]


@pytest.mark.parametrize("gaps", [1, 10])
def test_r9_mean_holds_up_to_the_scheduling_tolerance_plus_twice_the_error_over_the_gaps(gaps):
    error = 0.5 * MS
    tol = J.SCHEDULING_TOLERANCE_S + 2 * error / gaps
    assert tol == pytest.approx(J.r9_mean_tolerance_s(gaps, error))
    for off, ok in ((0.0, True), (tol - EPS, True), (tol + EPS, False), (-(tol - EPS), True), (-(tol + EPS), False)):
        j = J.r9_mean(_grid(0.020 + off, gaps + 1), 0.020, error=error)
        assert j is not None and j.rule == "R9" and j.ok is ok, (off, j)
        assert j.measured == pytest.approx(abs(off))


def test_r9_mean_25_ms_instead_of_20_fails_whatever_the_jitter():
    """INTERPRETATIONS R9: an ESC that reports every 25 ms instead of 20 FAILs on any bench: with ten gaps a bench of
    10 ms error still tells (the declared jitter: the test below, which reads as many gaps as it needs)."""
    j = J.r9_mean(_grid(0.025, 11), 0.020, error=0.010)
    assert j is not None and not j.ok and "25.000 ms" in j.text
    assert J.r9_mean([0.0], 0.020) is None  # no gap: nothing to judge


def test_r9_mean_takes_the_declared_jitter_at_its_two_ends_over_the_gaps():
    """INTERPRETATIONS R9 (amended 2026-12-02): the mean of n gaps is the span from its first report to its last over
    n, so the DUT's declared jitter counts at the two ends, over n. A correct ESC with a jittery timer (15 ms
    declared), its first report judged late by half of it and its last early by half, over ten 20 ms gaps: a mean
    1.5 ms short. Without the jitter in the bound it FAILed; with it, it passes."""
    jitter, gaps = 15 * MS, 10
    starts = [0.0075] + [k * 0.020 for k in range(1, gaps)] + [gaps * 0.020 - 0.0075]
    j = J.r9_mean(starts, 0.020, jitter=jitter)
    assert j is not None and j.judged and j.ok, j
    assert j.measured == pytest.approx(1.5 * MS)
    assert j.limit == pytest.approx(J.SCHEDULING_TOLERANCE_S + 2 * jitter / gaps) and j.error == 0.0
    assert J.r9_mean_tolerance_s(gaps, 0.0, jitter) == pytest.approx(J.SCHEDULING_TOLERANCE_S + 3 * MS)
    assert not J.r9_mean(starts, 0.020).ok  # the old reading: no jitter at the ends


def test_r9_mean_over_too_few_gaps_for_its_bound_is_not_judged():
    """R9: a judgement over so few gaps that the bound exceeds a quarter of the interval is not made (OBSERVE): ok,
    judged False, whatever the mean."""
    j = J.r9_mean(_grid(0.030, 4), 0.020, error=2 * MS, jitter=25 * MS)  # 1 ms + 2 x 27 ms / 3: 19 ms > 5 ms
    assert j is not None and not j.judged and j.ok
    assert not J.r9_mean_tells(3, 0.020, error=2 * MS, jitter=25 * MS)
    assert J.r9_mean_tells(10, 0.020, error=2 * MS)  # 1 + 0.4 ms: judged
    late = J.r18_mean(_grid(0.030, 4), 0.020, share=0.1, bitrate=500_000, error=2 * MS, jitter=25 * MS)
    assert late is not None and not late.judged and late.ok  # R18's mean is R9's: the same quarter


def test_r9_a_test_whose_purpose_it_is_reads_enough_gaps_that_25_ms_instead_of_20_fails_whatever_the_jitter():
    """A test whose purpose is R9 reads R9_GAPS gaps, or more where the DUT's declared jitter needs them (its part of
    the bound within the scheduling tolerance): over that many an ESC reporting every 25 ms instead of 20 FAILs, a
    correct one with its ends at the edges of its jitter passes. The bench's error never lengthens a test (a VM lane
    states 300 ms: it would read 600 gaps); where R9 is not the purpose, the fewest gaps over which the mean is
    judged at all, ten at most (more and the mean is not judged: OBSERVE)."""
    for error, jitter in ((0.0, 0.0), (2 * MS, 0.0), (2 * MS, 25 * MS), (10 * MS, 15 * MS)):
        n = J.r9_gaps_needed(0.020, error=error, jitter=jitter)
        assert n >= J.R9_GAPS and 2 * jitter / n <= J.SCHEDULING_TOLERANCE_S + EPS
        slow = J.r9_mean(_grid(0.025, n + 1), 0.020, error=error, jitter=jitter)
        assert slow is not None and slow.judged and not slow.ok, (error, jitter, n, slow)
        edge = error + jitter / 2  # each end's stamp off by the bench's error and half the jitter, inward
        ends = [edge] + [k * 0.020 for k in range(1, n)] + [n * 0.020 - edge]
        right = J.r9_mean(ends, 0.020, error=error, jitter=jitter)
        assert right is not None and right.ok, (error, jitter, n, right)
    assert J.r9_gaps_needed(0.020, error=2 * MS, jitter=25 * MS) == 50
    assert J.r9_gaps_needed(0.020, error=0.300) == J.R9_GAPS  # the bench's error: INCONCLUSIVE or OBSERVE, not longer
    few = J.r9_gaps_needed(0.020, error=2 * MS, jitter=3 * MS, purpose=False)
    assert few == 3 and J.r9_mean_tells(few, 0.020, error=2 * MS, jitter=3 * MS)
    assert not J.r9_mean_tells(few - 1, 0.020, error=2 * MS, jitter=3 * MS)
    assert J.r9_gaps_needed(0.020, error=0.300, purpose=False) == J.R9_GAPS  # at most ten: not judged there
    assert J.r9_gaps_needed(0.5, purpose=False) == 2


def test_r9a_gaps_the_first_gap_judged_is_the_second_to_the_third_report():
    starts = [1.0, 2.0, 3.0, 4.0]
    assert J.r9_judged(starts) == [2.0, 3.0, 4.0]
    assert J.r9_judged(starts, after_restart=False) == starts
    assert J.R9A_UNJUDGED == 2


def test_r9_single_gap_takes_the_lane_tolerance_and_the_jitter():
    tol, jitter = 1.5 * MS, 2 * MS
    allowance = tol + jitter
    for lo, hi, ok, op in ((0.020, 0.020, True, "<="), (0.020 + allowance - EPS, 0.021 + allowance, True, "<="),
                           (0.020 + allowance + EPS, 0.021 + allowance, False, "<="),
                           (0.010, 0.020 - allowance + EPS, True, ">="), (0.010, 0.020 - allowance - EPS, False, ">=")):
        j = J.r9_gap(lo, hi, 0.020, tolerance=tol, jitter=jitter)
        assert (j.ok, j.op) == (ok, op), (lo, hi, j)


def test_r9a_first_report_within_the_catalogue_s_restart_limit():
    assert J.r9a_limit_s(0.020) == pytest.approx(cat.restart_limit_s(0.020)) == pytest.approx(0.025)
    assert J.r9a_limit_s(0.010) == pytest.approx(0.013)  # max(3 ms, a quarter): the 3 ms floor
    assert J.r9a_limit_s(0.020, 0.100) == pytest.approx(cat.restart_limit_s(0.100))  # the longer of old and new
    assert J.r9a_limit_s(0.020, jitter=0.002) == pytest.approx(0.027)
    limit = J.r9a_limit_s(0.020)
    assert J.r9a_first(limit, limit).ok and J.r9a_first(limit - EPS, limit).ok
    assert not J.r9a_first(limit + EPS, limit).ok
    assert J.r9a_first(limit + MS - EPS, limit, error=MS).ok and not J.r9a_first(limit + MS + EPS, limit, error=MS).ok


def test_timing_tolerance_is_exact_in_simulated_time_and_a_tick_on_top_of_the_error_elsewhere():
    assert J.timing_tolerance("simulated", 0.005) == 0.0
    assert J.timing_tolerance("bus timestamp", 0.0005) == pytest.approx(0.0015)


# ------------------------------------------------------------------------------------------ R8
def test_r8_onset_window():
    early, late = J.r8_window_s(0.020)
    assert (early, late) == (pytest.approx(cat.COMM_LOSS_TIMEOUT_S), pytest.approx(cat.COMM_LOSS_TIMEOUT_S + 0.020))
    for onset, oks in ((0.200, (True, True)), (0.200 - EPS, (False, True)), (0.220, (True, True)),
                       (0.220 + EPS, (True, False))):
        assert tuple(j.ok for j in J.r8_onset(onset, 0.020)) == oks, onset
    assert all(j.ok for j in J.r8_onset(0.222, 0.020, jitter=0.002))  # the MSG1 carrying it may be late by the jitter
    assert not J.r8_onset(0.199, 0.020, jitter=0.002)[0].ok  # ... never early: the flag comes no sooner than 200 ms
    assert J.r8_onset(0.199, 0.020, error=MS)[0].ok  # within the bench's error: given to the DUT


def test_r8_flag_due_clear_before_200_ms_set_after_one_interval_more_free_between():
    assert J.r8_flag_due(0.150, 0.020) is False
    assert J.r8_flag_due(0.200 - EPS, 0.020) is False
    assert J.r8_flag_due(0.200, 0.020) is None and J.r8_flag_due(0.210, 0.020) is None
    assert J.r8_flag_due(0.220, 0.020) is None and J.r8_flag_due(0.220 + EPS, 0.020) is True
    assert J.r8_flag_due(0.199, 0.020, error=2 * MS) is None
    assert J.r8_flag_due(0.221, 0.020, error=2 * MS) is None


# ------------------------------------------------------------------------------------------ R2, 64 ms
@pytest.mark.parametrize("node", [1, 5, 17, 33])
def test_r2_slot_edges(node):
    slot = (node % 32) * 0.002
    assert J.r2_slot_start(slot, node).ok and not J.r2_slot_start(slot - EPS, node).ok
    assert J.r2_slot_start(slot - MS + EPS, node, error=MS).ok and not J.r2_slot_start(slot - MS - EPS, node, error=MS).ok
    assert J.r2_slot_end(slot + 0.002, node).ok and not J.r2_slot_end(slot + 0.002 + EPS, node).ok
    assert J.r2_slot_end(slot + 0.002 + MS - EPS, node, error=MS).ok


def test_answer_bound_64_ms():
    assert J.answer_bound(0.064).ok and not J.answer_bound(0.064 + EPS).ok
    assert J.answer_bound(0.064 + EPS, error=MS).ok
    assert J.answer_bound(0.070, rule="4.4.3-4").rule == "4.4.3-4"


# ------------------------------------------------------------------------------------------ F3
@pytest.mark.parametrize("previous", [0, 1, 30, 31])
def test_f3_plus_one_modulo_32_and_nothing_else(previous):
    """F3 at and around its limits: +1 holds (31 -> 0 is the wrap), +0 (stuck), +2 (one skipped), -1 and 31 -> 32
    (no modulo) break it."""
    want = (previous + 1) % 32
    assert J.f3_holds(previous, want) and J.f3_step(previous, want).ok
    assert J.f3_step(previous, want).wrapped == (previous == 31)
    for wrong in {previous, (previous + 2) % 32, (previous - 1) % 32, previous + 1 if previous == 31 else previous}:
        step = J.f3_step(previous, wrong)
        assert not step.ok and not J.f3_holds(previous, wrong) and step.expected == want, wrong
        assert str(step) == f"transfer id {wrong} after {previous}, expected {want}"


def test_f3_advance_and_frames_lost_from_a_capture():
    """A jump of k modulo 32 is explained by k - 1 frames missing from a capture; a stuck counter (advance 0) by
    none, not even 31 (32 frames lost would bring it round, but it did not move)."""
    assert J.f3_step(5, 5).advance == 0 and J.f3_step(31, 1).advance == 2 and J.f3_step(1, 0).advance == 31
    assert J.f3_step(30, 1).explained_by(2) and not J.f3_step(30, 1).explained_by(1)
    assert J.f3_step(4, 4).explained_by(31) is False and J.f3_step(4, 4).explained_by(0) is False
    assert J.f3_step(4, 3).explained_by(30)


# ------------------------------------------------------------------------------------------ R13 read-back
def test_r13_read_back_every_persisted_setting_kept_or_named_with_old_and_new():
    """R13 over every key of the catalogue's PERSISTED_SETTINGS: read back as written, nothing; one off by one (the
    least change), that one with what was written and what was read, in the order asked."""
    keys = [k for s in cat.PERSISTED_SETTINGS for k in s.keys]
    written = {k: i + 1 for i, k in enumerate(keys)}
    assert J.r13_read_back(written, dict(written)) == []
    for k in keys:
        got = J.r13_read_back(written, written | {k: written[k] + 1}, keys)
        assert got == [J.Differs(k, written[k], written[k] + 1)] and str(got[0]) == f"{k} {written[k]} -> {written[k] + 1}"
    two = J.r13_read_back(written, written | {"rotation": 0, "baud": 0}, ["baud", "rotation"])
    assert [d.key for d in two] == ["baud", "rotation"]


def test_r13_read_back_a_setting_one_side_lacks_and_the_keys_judged():
    """A setting not read back (or not expected) differs, shown as ``missing``; only ``keys`` are judged when given."""
    assert J.r13_read_back({"rotation": 1}, {}) == [J.Differs("rotation", 1, None)]
    assert [str(d) for d in J.r13_read_back({}, {"led_color": 2}, missing="none")] == ["led_color none -> 2"]
    assert J.r13_read_back({"rotation": 1, "led_color": 2}, {"rotation": 1, "led_color": 3}, ["rotation"]) == []


# ------------------------------------------------------------------------------------------ F4
def _answer(**kw):
    args = {"source": 5, "destination": 0, "transfer_id": 7, "kind": "response"} | kw
    wire = encode("set_freq", {"option": 0, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250}, **args)
    return Decoder().decode(wire)


def test_f4_an_answer_keeps_service_transfer_id_and_addresses():
    service = cat.spec("set_freq").type_id
    ok = J.f4_mismatches(_answer(), service=service, transfer_id=7, requester=0, asked=5)
    assert ok == []
    for kw, word in ((dict(transfer_id=8), "transfer id"), (dict(destination=3), "destination"),
                     (dict(source=6), "source"), (dict(kind="request"), "request bit")):
        got = J.f4_mismatches(_answer(**kw), service=service, transfer_id=7, requester=0, asked=5)
        assert len(got) == 1 and word in got[0], (kw, got)
        assert J.f4_pairs(got)  # one field off: still this request's answer, failed with the field named
    two = J.f4_mismatches(_answer(transfer_id=8, source=6), service=service, transfer_id=7, requester=0, asked=5)
    assert len(two) == 2 and not J.f4_pairs(two)
    assert "service" in J.f4_mismatches(_answer(), service=service + 1, transfer_id=7, requester=0, asked=5)[0]


def test_f4_set_id_answers_from_any_node():
    assert J.asked_node("set_id", 5) is None and J.asked_node("set_freq", 5) == 5
    assert J.f4_mismatches(_answer(source=9), service=cat.spec("set_freq").type_id, transfer_id=7, requester=0,
                           asked=None) == []


def test_f4_reads_a_raw_id_too():
    f = _answer(transfer_id=3)
    raw = J.Addressed(Kind.RESPONSE, f.type_id, f.transfer_id, f.destination, f.source)
    assert J.f4_mismatches(raw, service=f.type_id, transfer_id=3, requester=0, asked=5) == []


def test_f4_the_host_pairs_a_response_as_f4_answers_says():
    """The host's pairing (``HostProtocol._match``) is F4's one rule: an exact answer wins over an open request it
    is one field off from, one field off still pairs (named), two fields off pairs with none."""
    from ckesc.protocol.host import HostProtocol, Overheard, Response

    fields = {"option": 0, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250}
    for kw, expect in ((dict(transfer_id=1), 1), (dict(transfer_id=0, source=6), 0), (dict(transfer_id=2), 0),
                       (dict(transfer_id=2, source=6), None)):
        host = HostProtocol(node_id=0)
        pending = [host.request("set_freq", fields, destination=5, now=0.0, timeout=1.0)[1] for _ in range(2)]
        assert [p.transfer_id for p in pending] == [0, 1]
        answer = _answer(**kw)
        asked = [(p.service, p.transfer_id, 0, J.asked_node(p.name, p.destination)) for p in pending]
        assert J.f4_answers(answer, asked) == expect, kw
        got = host.receive(encode("set_freq", fields, kind="response", source=kw.get("source", 5), destination=0,
                                  transfer_id=kw["transfer_id"]))[0]
        if expect is None:
            assert isinstance(got, Overheard) and host.pending == pending, kw
        else:
            assert isinstance(got, Response) and got.pending is pending[expect], kw
            assert bool(got.mismatch) == (kw != dict(transfer_id=1)), kw


def test_judgement_is_a_frozen_record_with_its_text():
    j = J.r9a_first(0.030, 0.025, what="the first MSG1")
    with pytest.raises(AttributeError):
        j.limit = 1.0  # type: ignore[misc]
    assert not j.ok and j.margin == pytest.approx(-0.005) and "R9a" in str(j) and "broken" in str(j)


# ------------------------------------------------------------------------------------------ R20
def test_r20_reports_go_on_within_bus_off_recovery_and_two_msg1_intervals_plus_the_error():
    """128 x 11 recessive bits at 500 kbit/s (2.816 ms) and two 20 ms intervals; the bench's error given on top; no
    report at all is outside any bound."""
    bound = J.r20_bound_s(0.020, bitrate=500_000)
    assert bound == pytest.approx(0.002816 + 0.040)
    error = 2 * MS
    for delay, ok in ((bound, True), (bound + error - EPS, True), (bound + error + EPS, False), (float("inf"), False)):
        j = J.r20_back(delay, 0.020, bitrate=500_000, error=error)
        assert j.rule == "R20-recovery" and j.ok is ok, (delay, j)
    assert J.R20_UNJUDGED == {"R9", "R9a", "F3"}
