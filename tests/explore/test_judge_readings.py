"""The explorer's judge reads R8, R9 and R9a as the suite does (issue #28: it now calls ckesc.protocol.judgements).
Each case is one place where the judge and the suite disagreed before, judged as INTERPRETATIONS.md reads it."""

from __future__ import annotations

from ckesc.explore.judge import Params, _comm_fault_expected, _interval_finding
from ckesc.explore.oracle import State
from ckesc.protocol import catalogue as cat
from ckesc.protocol.frame import frame_bits

FRAME_S = frame_bits(8) / cat.DEFAULT_BITRATE
INTERVALS = {"msg1": 0.020, "msg2": 0.100, "msg3": 0.500}


def _state(t: float = 0.0) -> State:
    return State(t, "set_freq", "normal", dict(INTERVALS), 0, "set_freq")


def _r9(stamps: list[float], jitter: float = 0.0) -> list:
    return _interval_finding(_state(), "msg1", stamps, stamps[-1] + 1.0, 0.020, 0.0, Params(jitter=jitter), FRAME_S)


def test_a_declared_jitter_enters_the_mean_at_its_two_ends_over_the_gaps():
    """R9 (amended 2026-12-02, as the suite reads it, ``judgements.r9_mean``): the DUT's declared jitter widens the
    mean of n gaps by twice the jitter over n, its two ends only. MSG1 every 21.5 ms instead of 20 over four gaps
    fails with no jitter and with 0.5 ms (1.25 ms of bound); with 50 ms declared the bound over four gaps exceeds a
    quarter of the interval and the mean is not judged (OBSERVE), which the judge says by no finding."""
    stamps = [0.1 + k * 0.0215 for k in range(6)]
    assert _r9(stamps) and _r9(stamps, jitter=0.0005)
    assert not _r9(stamps, jitter=0.050)
    assert not _r9([0.1 + k * 0.020 for k in range(6)], jitter=0.050)


def test_the_gap_to_the_third_report_is_judged():
    """R9a-gaps: the gaps up to and including the second report after the event are OBSERVE, the gap from the
    second to the third is R9's (the judge skipped it too, from its ``[2:]``)."""
    assert _r9([0.010, 0.030, 0.055, 0.075, 0.095])  # second to third 25 ms: the mean of three gaps 21.7 ms
    assert not _r9([0.010, 0.035, 0.055, 0.075, 0.095])  # first to second 25 ms: not judged


def test_the_comm_loss_flag_is_never_due_before_200_ms_whatever_the_jitter():
    """R8: set no earlier than 200 ms after the last command. The MSG1 that carries the flag may come late by the
    DUT's jitter, which widens the late edge only (as the suite's test does); the judge widened both."""
    state = State(0.0, "start", "normal", dict(INTERVALS))
    p = Params(jitter=0.010)
    last = 1.0
    assert _comm_fault_expected(last + 0.195, [last], [0.0], state, p) is False
    assert _comm_fault_expected(last + 0.2285, [last], [0.0], state, p) is None  # within one interval + jitter
    assert _comm_fault_expected(last + 0.235, [last], [0.0], state, p) is True


def _across_a_malformed_frame(change) -> list:
    """The judge's findings on a faultless emulated ESC's frames, given a malformed frame (a multi-frame start of a
    MSG Control suspend) at 0.5 s, with ``change(frames, at)`` applied to the ESC's MSG1s after it."""
    import can

    from ckesc.emulator.model import EscConfig, EscModel, factory_nvm
    from ckesc.explore.judge import judge
    from ckesc.explore.oracle import SETTING_KEYS, Oracle
    from ckesc.protocol import malformed as r17
    from ckesc.protocol.frame import Decoder

    cfg = EscConfig(node_id=1, boot_time=0.0, report_delay=0.0)
    nvm = factory_nvm(cfg)
    esc = EscModel(cfg, dict(nvm))
    esc.power_on(0.0)
    oracle = Oracle({"node_id": 1, **{k: nvm[k] for k in SETTING_KEYS}}, powered_at=0.0, start=0.0)
    sent = []
    bad = r17.build("msg_control", {"option": 0, "command": cat.MSG_CONTROL_SUSPEND}, r17.START, source=0, node_id=1,
                    others=[], transfer_id=lambda _: 3)[0]
    at, until = 0.5, 1.5
    for t in (at, until):
        while (d := esc.next_deadline()) is not None and d <= t:
            sent.extend(esc.poll(d))
        sent.extend(esc.poll(t))
        if t == at:
            msg = can.Message(arbitration_id=bad.frames[0].arbitration_id, data=bad.frames[0].data, is_extended_id=True,
                              timestamp=at)
            esc.receive(msg, at)
            oracle.malformed_frame(msg, "msg_control", r17.START, bad.what)
    oracle.finish(until)
    decoder = Decoder()
    frames = [decoder.decode(w._replace(timestamp=w.timestamp + FRAME_S)) for w in sent]
    return judge(oracle, change(frames, at), 0.0, until, Params())


def _msg1_after(frames: list, at: float, tid) -> list:
    """``frames`` with each MSG1 after ``at`` given transfer id ``tid(old, k)`` (k counting them from 0), or dropped (None)."""
    out, k = [], 0
    for f in frames:
        if f.name == "msg1" and f.timestamp > at:
            new = tid(f.transfer_id, k)
            k += 1
            if new is None:
                continue
            f.transfer_id = new  # (the frames are this case's own)
        out.append(f)
    return out


def test_a_reset_across_a_malformed_frame_is_a_report_gap_with_a_transfer_id_restart():
    """R17/R19 (issue #35: one reading of a reset in every mode, ``judgements.r19_report_restart``): the explorer took
    any transfer id jump after a malformed frame for a reset, and any report later than R9a's restart bound from the
    frame, counting on or not. A reset is a gap longer than a restart may take across which the counter started again:
    a jump with no gap is F3's, a late report counting on R9's on its gap (the live bus rules find both, and the
    runner makes them cite R17 after a malformed frame)."""
    assert _across_a_malformed_frame(lambda frames, at: frames) == []
    resets = lambda found: [f.what for f in found if f.kind == "reset"]  # noqa: E731
    # the ESC reset: no MSG1 for 300 ms, then its counter from 0
    found = _across_a_malformed_frame(lambda fs, at: _msg1_after(fs, at, lambda old, k: None if k < 15 else k - 15))
    assert resets(found) == ["MSG1 restarted after a malformed frame: " + found[0].what.split(": ", 1)[1]]
    assert found[0].requirements == ["R17", "R19"]
    # a jump with no gap: not a reset (the old judge: 'MSG1 transfer id 25 -> 30')
    assert resets(_across_a_malformed_frame(lambda fs, at: _msg1_after(fs, at, lambda old, k: (old + 5) % 32))) == []
    # late, counting on (or the frames between lost, F3's counter having gone on): not a reset (the old judge: 'no
    # MSG1 for 28.0 ms after it')
    for late in (lambda old, k: None if k < 15 else (old - 15) % 32, lambda old, k: None if k < 15 else old):
        assert resets(_across_a_malformed_frame(lambda fs, at, late=late: _msg1_after(fs, at, late))) == []
