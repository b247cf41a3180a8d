"""R17 as the bus reader reads the host's own frames (issue #35 item 2: the explorer's judge takes the bus's own rules
from the reader). Where the two disagreed, the explorer's reading won: a malformed frame of the host's (R17: not a
single-frame transfer of its table's length) is one the ESC ignores, so the reader takes it as nothing the ESC acted
on. Before, the reader took a malformed MSG Control suspend (a multi-frame start) for a suspend and judged no reset
across it (the explorer's own reset check found it: two keepers of one rule), and took a malformed request for one
that asks, so an answer to it passed F4."""

from __future__ import annotations

import can

from ckesc.emulator.config import EscConfig
from ckesc.emulator.model import EscModel
from ckesc.evidence.rules import BusRules
from ckesc.evidence.taken import taken
from ckesc.protocol import catalogue as cat
from ckesc.protocol import malformed as r17
from ckesc.protocol.frame import encode, frame_bits
from ckesc.protocol.transfer import TRANSFER_ID_MASK

NODE = 1
AT = 0.51  # the malformed frame (between two MSG1s)
END = 1.5
SUSPEND = {"option": 0, "command": cat.MSG_CONTROL_SUSPEND}
MSG1_ID = cat.spec("msg1").type_id


def _bad(name: str, fields: dict, form: str):
    return r17.build(name, fields, form, source=0, node_id=NODE, others=[], transfer_id=lambda _: 3)[0].frames[0]


def _heard(host: can.Message, change=None) -> list[can.Message]:
    """A faultless emulated ESC's frames up to END, the host's ``host`` frame at its time (its own, is_rx False),
    each ESC frame stamped at its end; ``change(tid, k)`` gives each MSG1 after AT (k counting from 0) its transfer
    id, or drops it (None)."""
    esc = EscModel(EscConfig(node_id=NODE, boot_time=0.0, report_delay=0.0))
    esc.power_on(0.0)
    sent = []
    for t in (AT, END):
        while (d := esc.next_deadline()) is not None and d <= t:
            sent.extend(esc.poll(d))
        sent.extend(esc.poll(t))
        if t == AT:
            esc.receive(host, AT)
    out, k = [host], 0
    for w in sent:
        data = bytes(w.data)
        if change is not None and (w.arbitration_id >> 8) & 0xFFFF == MSG1_ID and w.timestamp > AT:
            tid = change(data[-1] & TRANSFER_ID_MASK, k)
            k += 1
            if tid is None:
                continue
            data = data[:-1] + bytes(((data[-1] & ~TRANSFER_ID_MASK) | tid,))
        out.append(can.Message(arbitration_id=w.arbitration_id, data=data, is_extended_id=True,
                               timestamp=w.timestamp + frame_bits(len(data)) / cat.DEFAULT_BITRATE))
    return sorted(out, key=lambda m: m.timestamp)


def _read(messages: list[can.Message]) -> list:
    rules = BusRules(tolerance=0.0, complete=True, power_known=True)
    return [v for m in messages for v in rules.feed_message(m)]


def _host(wire) -> can.Message:
    return can.Message(arbitration_id=wire.arbitration_id, data=wire.data, is_extended_id=True, timestamp=AT,
                       is_rx=False)


def test_r17_classes_are_not_taken_and_a_single_frame_with_toggle_one_may_be():
    for form in (r17.START, r17.MIDDLE, r17.END, r17.SHORT, r17.LONG):
        w = _bad("msg_control", SUSPEND, form)
        assert not taken(w.arbitration_id, w.data), form
    w = _bad("msg_control", SUSPEND, r17.TOGGLE)
    assert taken(w.arbitration_id, w.data)  # R17-toggle: OBSERVE, may be taken
    w = encode("msg_control", SUSPEND, source=0, transfer_id=3)
    assert taken(w.arbitration_id, w.data)


def test_a_reset_across_a_malformed_suspend_is_found_by_the_reader():
    """R17/R19: across a malformed MSG Control suspend (a multi-frame start, which the ESC ignores), no MSG1 for
    300 ms and then its counter from 0 is a reset; the old reader took the frame for a suspend and judged nothing.
    A jump with no gap is F3's, not a reset; late but counting on is not a reset either; the faultless ESC: nothing."""
    host = _host(_bad("msg_control", SUSPEND, r17.START))
    assert _read(_heard(host)) == []
    found = _read(_heard(host, lambda tid, k: None if k < 15 else (k - 15) % 32))
    resets = [v for v in found if v.check == "reset"]
    assert [v.rules for v in resets] == [("R19", "R17")], [str(v) for v in found]
    assert "msg1 stopped for" in resets[0].message
    jumped = _read(_heard(host, lambda tid, k: (tid + 5) % 32))
    assert [v.check for v in jumped] == ["transfer-id"], [str(v) for v in jumped]
    late = _read(_heard(host, lambda tid, k: None if k < 15 else (tid - 15) % 32))
    assert "reset" not in {v.check for v in late}, [str(v) for v in late]


def test_a_valid_suspend_is_still_a_suspend_to_the_reader():
    """The counterpart: a well-formed suspend stops reporting, and nothing is judged across it."""
    host = _host(encode("msg_control", SUSPEND, source=0, transfer_id=3))
    assert _read(_heard(host)) == []


def test_an_answer_to_a_malformed_request_answers_nothing():
    """R17: a malformed request (a multi-frame start of Set Rotation) asks nothing, so a response with its transfer id
    answers no request of the host's (F4). The old reader paired it with the malformed request and passed it."""
    wire = _bad("set_rotation", {"rotation": 1}, r17.START)
    host = _host(wire)
    answer = encode("set_rotation", {"rotation": 1}, kind="response", source=NODE, destination=0, transfer_id=3)
    reply = can.Message(arbitration_id=answer.arbitration_id, data=answer.data, is_extended_id=True, timestamp=AT + 0.004)
    found = _read([host, reply])
    assert [(v.rules, v.check) for v in found] == [(("F4",), "response-match")], [str(v) for v in found]
    good = encode("set_rotation", {"rotation": 1}, source=0, destination=NODE, transfer_id=3)
    assert _read([_host(good), reply]) == []


def test_check_log_reads_the_malformed_suspend_as_the_live_rules_do(tmp_path, capsys):
    """One reader in every mode: ``ckesc check-log --power-on`` over a capture of the same frames finds the same reset
    (before, it took the malformed frame for a suspend too, and judged nothing across it)."""
    from ckesc.cli import main

    host = _host(_bad("msg_control", SUSPEND, r17.START))
    log = tmp_path / "trace.log"
    log.write_text("".join(f"({m.timestamp:.6f}) can0 {m.arbitration_id:08X}#{bytes(m.data).hex().upper()}\n"
                           for m in _heard(host, lambda tid, k: None if k < 15 else (k - 15) % 32)))
    assert main(["check-log", "--complete", "--power-on", str(log)]) == 1
    out = capsys.readouterr().out
    assert "a reset the host did not make: msg1 stopped for" in out, out


def test_the_reader_decodes_no_frame_and_reads_r17_as_the_decoder_does(monkeypatch):
    """Issue #35 ("each frame decoded once"): the suite's link decodes every frame; the reader beside it decoded the
    host's frames once more to tell a malformed one (``taken``). It now reads R17's classes from the CAN id and the
    bytes with the decoder's own form checks (``frame.read_form``), and decodes nothing: with the decoder's field
    reading broken, the reader reads a bus of every R17 class of a command as before, and ``taken`` says of each
    frame what the decoder's verdict on it says."""
    from ckesc.protocol.errors import DecodeError, LengthError, TailError
    from ckesc.protocol.frame import Decoder, WireFrame

    frames = [w for f in (*r17.FORMS, r17.TOGGLE) for name, fields in (("msg_control", SUSPEND), ("set_rotation", {"rotation": 1}))
              if r17.applies(cat.spec(name), f) for w in r17.build(name, fields, f, source=0, node_id=NODE, others=[2],
                                                                   transfer_id=lambda _: 3)[0].frames]
    decoder = Decoder(track_requests=False)
    for w in frames:
        try:
            decoder.decode(WireFrame(w.arbitration_id, bytes(w.data)))
            want = True
        except TailError:
            want = w.data[-1] & 0xC0 == 0xC0  # a single frame with toggle 1: R17-toggle, may be taken
        except LengthError:
            want = False
        except DecodeError:
            want = True
        assert taken(w.arbitration_id, bytes(w.data)) == want, w
    traces = [_heard(_host(w)) for w in frames]  # (the emulated ESC decodes what it hears: played before)
    before = [[v.check for v in _read(t)] for t in traces]

    def broken(*_a, **_k):
        raise AssertionError("the reader decoded a frame")

    monkeypatch.setattr(Decoder, "decode", broken)
    assert [[v.check for v in _read(t)] for t in traces] == before  # (a decode would raise here)
