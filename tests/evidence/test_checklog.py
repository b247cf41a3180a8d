"""``ckesc check-log``: captures in candump, ASC and BLF form (written with python-can's writers from
emulator traffic), foreign traffic, damaged lines with their numbers, exit codes, JSON and HTML."""

from __future__ import annotations

import json
from pathlib import Path

import can
import pytest

from ckesc.cli import main
from ckesc.evidence.checklog import check_capture
from ckesc.evidence.logs import read_candump
from ckesc.protocol import catalogue as cat
from ckesc.protocol.ids import message_id

from .traffic import ScriptedHost

pytestmark = pytest.mark.xdist_group(__name__)  # its module-scoped runs are made once: its tests share one worker

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "logs" / "field-ardupilot.log"


@pytest.fixture(scope="module")
def traffic() -> dict[str, list[can.Message]]:
    """Emulator traffic, faultless and with a framing fault, kept as python-can messages."""
    out = {}
    for label, faults in (("good", ()), ("toggle", ("tail_toggle_set",))):
        host = ScriptedHost((1, 2), faults, keep=True)
        try:
            out[label] = host.script().messages
        finally:
            host.close()
    return out


def write(path: Path, messages: list[can.Message]) -> Path:
    with can.Logger(str(path)) as writer:  # python-can picks the writer by suffix
        for msg in messages:
            writer.on_message_received(msg)
    return path


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_formats_good_and_broken(tmp_path, traffic, capsys, suffix):
    good = write(tmp_path / f"good{suffix}", traffic["good"])
    assert main(["check-log", str(good), "--complete"]) == 0
    out = capsys.readouterr().out
    assert "verdict: no rule broken" in out and "node   1 [esc]" in out and "msg1:" in out
    bad = write(tmp_path / f"toggle{suffix}", traffic["toggle"])
    assert main(["check-log", str(bad), "--complete"]) == 1
    out = capsys.readouterr().out
    assert "[F2 4.1.3-toggle SHALL]" in out and "toggle=1" in out and "verdict: RULES BROKEN" in out


def test_json_and_html(tmp_path, traffic, capsys):
    log = write(tmp_path / "toggle.log", traffic["toggle"])
    out_json, out_html = tmp_path / "r.json", tmp_path / "r.html"
    assert main(["check-log", str(log), "--json", str(out_json), "--html", str(out_html)]) == 1
    doc = json.loads(out_json.read_text())
    assert doc["frames"] == len(traffic["toggle"]) and doc["violations"]["by_rule"]["F2"] > 0
    first = doc["violations"]["first"][0]
    assert first["rules"] == ["F2", "4.1.3-toggle"] and first["frames"][0].startswith("(")
    assert doc["nodes"]["1"]["intervals"]["msg1"]["count"] > 50 and doc["nodes"]["1"]["comm_loss"]
    page = out_html.read_text()
    assert page.startswith("<!doctype html>") and "<svg" in page and "4.1.3-toggle" in page and "http" not in page


def test_foreign_traffic_and_damaged_lines(capsys):
    """The committed field capture: ArduPilot's own 20000/20010 frames and a DroneCAN GPS are counted, not
    judged; three damaged lines are listed with their numbers; no rule is broken."""
    assert main(["check-log", str(FIXTURE)]) == 0
    out = capsys.readouterr().out
    for line in ("line 9: data '00000000000' has an odd number of hex digits (11)", "line 30: not a candump line",
                 "line 61: not a candump line", "node  50 [foreign] 2 frames: foreign message 341 2", "node  10 [host]"):
        assert line in out
    s = check_capture(str(FIXTURE))
    assert s["damaged"]["count"] == 3 and s["violations"]["count"] == 0


def test_candump_reader_reads_every_form(tmp_path):
    """The fast path and the exact parser agree: direction flags, 11-bit, remote and error frames, the
    display form; a line without a timestamp is reported, not guessed."""
    path = tmp_path / "forms.log"
    path.write_text("(1.000000) can0 1F4E5201#000000000000C0 R\n"
                    "(1.000100) can0 1F4E5201#000000000000C1 T\n"
                    "(1.000200) can0 123#11\n"
                    "(1.000300) can0 1F4E5201#R\n"
                    "(1.000400) can0 20000004#0000000000000000\n"
                    "(1.000500)  can0  1F4E5201   [7]  00 00 00 00 00 00 C2\n"
                    "1F4E5201#000000000000C3\n"
                    "\n# a comment\n"
                    "(1.000600) can0 1F4E520G#00\n")
    bad = []
    frames = list(read_candump(str(path), lambda *a: bad.append(a)))
    assert [(f[0], f[3], f[4], f[5], f[6]) for f in frames] == [
        (0x1F4E5201, True, False, False, False), (0x1F4E5201, True, False, False, True), (0x123, False, False, False, False),
        (0x1F4E5201, True, True, False, False), (0x4, True, False, True, False), (0x1F4E5201, True, False, False, False)]
    assert [b[0] for b in bad] == [7, 10] and "no timestamp" in bad[0][2]


def test_exit_codes_for_unreadable_input(tmp_path, capsys):
    assert main(["check-log", str(tmp_path / "missing.log")]) == 2
    junk = tmp_path / "junk.log"
    junk.write_text("not a capture\n")
    assert main(["check-log", str(junk)]) == 2
    assert "nothing readable" in capsys.readouterr().err
    broken = tmp_path / "broken.blf"
    broken.write_bytes(b"LOGG" + bytes(200))
    assert main(["check-log", str(broken)]) == 2
    assert main(["check-log", str(junk), "--bitrate", "123"]) == 2


@pytest.mark.parametrize("name, content", [("empty.log", b""), ("comments.log", b"# a header, no frame\n\n"),
                                           ("empty.blf", b""), ("empty.asc", b"")])
def test_nothing_readable_is_exit_2(tmp_path, capsys, name, content):
    (tmp_path / name).write_bytes(content)
    assert main(["check-log", str(tmp_path / name)]) == 2
    err = capsys.readouterr().err
    assert "nothing readable" in err and "no rule broken" not in err


def test_a_header_only_blf_is_exit_2(tmp_path, capsys):
    header_only = write(tmp_path / "none.blf", [])
    assert main(["check-log", str(header_only)]) == 2
    assert "nothing readable" in capsys.readouterr().err


@pytest.mark.parametrize("keep", [0.5, 0.9])
def test_a_blf_cut_short_is_truncated_with_its_counts(tmp_path, traffic, capsys, keep):
    full = write(tmp_path / "full.blf", traffic["good"])
    data = full.read_bytes()
    cut = tmp_path / "cut.blf"
    cut.write_bytes(data[: int(len(data) * keep)])
    assert main(["check-log", str(full), "--complete"]) == 0
    capsys.readouterr()
    assert main(["check-log", str(cut)]) == 2
    err = capsys.readouterr().err
    declared = len(traffic["good"])
    assert "truncated" in err and f"of the {declared} objects its BLF header declares" in err
    assert f"of the {len(data)} bytes" in err
    assert main(["check-log", str(cut), "--allow-truncated"]) == 0
    captured = capsys.readouterr()
    assert "warning" in captured.err and "truncated" in captured.err and "verdict: no rule broken" in captured.out


def test_decode_says_a_binary_file_is_not_candump_text(tmp_path, traffic, capsys):
    blf = write(tmp_path / "capture.blf", traffic["good"])
    assert main(["decode", str(blf)]) == 2
    err = capsys.readouterr().err
    assert "not candump text" in err and "check-log" in err
    gz = write(tmp_path / "capture.log.gz", traffic["good"])
    assert main(["decode", str(gz)]) == 2
    assert "gzip" in capsys.readouterr().err
    noise = tmp_path / "noise.bin"
    noise.write_bytes(bytes(range(256)) * 8)
    assert main(["decode", str(noise)]) == 2
    assert "a binary file" in capsys.readouterr().err


def test_the_dut_profile_gives_its_declared_jitter_as_a_run_and_a_soak_do(tmp_path, capsys):
    """A capture of an ESC whose reports wander by its declared jitter (a late MSG1 followed by one on time, as the
    clean-room ESC's Python timer does): check-log judged it without the jitter its profile declares and found gaps
    "closer than the shortest legal interval" that the run and the soak of the same bench, given the profile, do
    not; ``--profile`` gives it the same jitter, so one ESC is judged alike by every mode."""
    msg1 = cat.spec("msg1")
    stamps = [0.020 * k for k in range(60)]
    stamps[30] += 0.008  # one report 8 ms late: a 28 ms gap, then a 12 ms one
    messages = [can.Message(timestamp=t, arbitration_id=message_id(msg1.priority, msg1.type_id, 1),
                            data=bytes(7) + bytes([0xC0 | (k % 32)]), is_extended_id=True)
                for k, t in enumerate(stamps)]
    log = write(tmp_path / "jittery.log", messages)
    assert main(["check-log", str(log)]) == 1
    assert "never closer than the shortest legal interval" in capsys.readouterr().out
    profile = tmp_path / "jittery.toml"
    profile.write_text('[dut]\nname = "jittery"\n[timing]\njitter_s = 0.010\n')
    assert main(["check-log", str(log), "--profile", str(profile)]) == 0, capsys.readouterr().out
    assert main(["check-log", str(log), "--profile", str(tmp_path / "none.toml")]) == 2
    assert "--profile" in capsys.readouterr().err
