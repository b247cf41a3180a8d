"""The ``ckesc`` command line: decode, encode, frames (called as ``main([...])``, plus real subprocess runs)."""

from __future__ import annotations

import io
import itertools
import json
import shutil
import subprocess
import sys
from pathlib import Path

import can
import pytest

import conformance
from ckesc.cli import main
from ckesc.evidence.candump import decode_lines, parse_candump
from ckesc.protocol import BY_NAME, CATALOGUE

MSG1_LINE = "(1700000000.123456) can0 1F4E5205#3412E8030181C0"  # MSG1 from node 5, LOWEST, tid 0


def _script() -> str:
    path = Path(sys.executable).with_name("ckesc")
    found = str(path) if path.exists() else shutil.which("ckesc")
    if found is None:
        pytest.skip("the ckesc console script is not installed (pip install -e .)")
    return found


def _decode(tmp_path: Path, capsys, text: str, *extra: str) -> tuple[int, list[dict], str]:
    log = tmp_path / "in.log"
    log.write_bytes(text.encode() if isinstance(text, str) else text)
    code = main(["decode", str(log), *extra])
    out, err = capsys.readouterr()
    return code, [json.loads(line) for line in out.splitlines()], err


def _encode(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(["encode", *argv])
    out, err = capsys.readouterr()
    return code, out.strip(), err


# ---------------------------------------------------------------------------------------------------
# decode: good lines


def test_decode_candump_log_line(tmp_path, capsys):
    code, (rec,), err = _decode(tmp_path, capsys, MSG1_LINE + "\n")
    assert code == 0 and err == ""
    assert rec["id"] == 20050 and rec["name"] == "msg1" and rec["kind"] == "message"
    assert (rec["source"], rec["destination"], rec["priority"], rec["transfer_id"]) == (5, None, 31, 0)
    assert rec["fields"] == {"speed": 0x1234, "pwm": 1000, "status": 0x8101}
    assert rec["decoded"]["status"] == ["selftest_a_output_high", "running", "direction_ccw"]
    assert (rec["line"], rec["timestamp"], rec["channel"]) == (1, 1700000000.123456, "can0")
    assert (rec["can_id"], rec["data"]) == ("1F4E5205", "3412E8030181C0")


def test_decode_bare_line_and_display_form(tmp_path, capsys):
    text = "1F4E5205#3412E8030181C1\n  can0  1F4E5205   [7]  34 12 E8 03 01 81 C2   '4.#.....'\n"
    code, recs, _ = _decode(tmp_path, capsys, text)
    assert code == 0
    assert [r["transfer_id"] for r in recs] == [1, 2]
    assert recs[0]["timestamp"] is None and recs[0]["channel"] is None
    assert recs[1]["channel"] == "can0"
    assert all(r["fields"]["speed"] == 0x1234 for r in recs)


def test_decode_throttle_channels_are_a_list_of_ints(tmp_path, capsys):
    # R4 vector: [0x123, 0x456, 0x789, 0xABC], group 1 -> 23 61 45 89 C7 AB 01 + tail
    code, (rec,), _ = _decode(tmp_path, capsys, "004E8500#23614589C7AB01C3\n")
    assert code == 0
    assert rec["name"] == "raw_command_12b" and rec["priority"] == 0 and rec["transfer_id"] == 3
    assert rec["fields"] == {"channels": [0x123, 0x456, 0x789, 0xABC], "group": 1}
    assert all(type(c) is int for c in rec["fields"]["channels"])


def test_decode_nibble_order_option(tmp_path, capsys):
    code, (rec,), _ = _decode(tmp_path, capsys, "004E8500#231645897CAB01C0\n", "--nibble-order", "swapped")
    assert code == 0 and rec["fields"]["channels"] == [0x123, 0x456, 0x789, 0xABC]


def test_decode_services_and_241_response_by_the_request_option(tmp_path, capsys):
    lines = [
        "10D68580#010A32FAC4",  # set_freq request 0 -> 5, write 10/50/250, tid 4
        "10D60085#010A32FAC4",  # its response 5 -> 0
        "10F18580#01C7",  # 241 request option 1 ("this run"), tid 7
        "10F10085#6400000003000000C7",  # too long: a decode error in between must not lose the request
        "10F10085#64000000030000C7",  # the response: run_time 100 s, 3 runs
    ]
    code, recs, _ = _decode(tmp_path, capsys, "\n".join(lines) + "\n")
    assert code == 1
    req, resp, req241, bad, resp241 = recs
    assert (req["kind"], req["source"], req["destination"], req["transfer_id"]) == ("request", 0, 5, 4)
    assert req["fields"] == {"option": 1, "msg1_interval": 10, "msg2_interval": 50, "msg3_interval": 250}
    assert (resp["kind"], resp["source"], resp["destination"]) == ("response", 5, 0)
    assert bad["line"] == 4 and bad["reason"] == "wrong-length"
    assert resp241["fields"] == {"run_time": 100, "runs": 3, "info_7": 0}


def test_blank_lines_comments_and_crlf(tmp_path, capsys):
    text = "# capture of bench 3\r\n\r\n   \r\n" + MSG1_LINE + "\r\n# end\r\n"
    code, recs, _ = _decode(tmp_path, capsys, text)
    assert code == 0
    assert [r["line"] for r in recs] == [4]
    assert recs[0]["fields"]["pwm"] == 1000


def test_decode_reads_stdin(monkeypatch, capsys):
    monkeypatch.setattr(sys, "stdin", io.StringIO(MSG1_LINE + "\n"))
    assert main(["decode"]) == 0
    assert json.loads(capsys.readouterr().out)["name"] == "msg1"


def test_decode_is_streamed_line_by_line():
    def endless():
        yield MSG1_LINE
        while True:
            yield "garbage"

    first, second = itertools.islice(decode_lines(endless()), 2)  # would never return if the input were read whole
    assert first["name"] == "msg1" and second["line"] == 2 and "error" in second


# ---------------------------------------------------------------------------------------------------
# decode: every kind of bad line gives {"error", "line"} and exit 1


@pytest.mark.parametrize(
    "line, reason, words",
    [
        ("123#1122", "not-extended-data-frame", "29-bit"),  # standard id: the protocol's own error
        ("(1.0) can0 7DF#02010D", "not-extended-data-frame", "standard 11-bit id 0x7DF"),
        ("1F4E5205#R", "not-extended-data-frame", "remote frame"),
        ("1F4E5205#R7", "not-extended-data-frame", "remote frame"),
        ("(1700000000.5) can0 20000080#0000000000000000", "not-extended-data-frame", "error frame"),
        ("  can0  20000004   [8]  00 08 00 00 00 00 00 00   ERRORFRAME", "not-extended-data-frame", "error frame"),
        ("1F4E5205#3412E", "odd-hex", "odd number of hex digits"),
        ("1F4E5205#3412XY", "bad-data", "not hex"),
        ("hello world", "not-candump", "not a candump line"),
        ("(1.0) can0 1F4E5205#3412E8030181C0 extra", "not-candump", "not a candump line"),
        ("(soon) can0 1F4E5205#3412E8030181C0", "bad-timestamp", "timestamp"),
        ("1F4E52G5#00", "bad-id", "hex digits"),
        ("104E85000#00", "bad-id", "hex digits"),
        ("1F4E5205##13412E8030181C0", "not-classic-can", "CAN FD"),
        ("  can0  1F4E5205   [7]  34 12 E8", "bad-data", "announces 7"),
        # the issue's own example has 8 data bytes; MSG1 is 6 + tail
        ("(1700000000.123456) can0 1F4E5205#341234E8030181C0", "wrong-length", "expected 7"),
        ("1F4E5205#3412E8030181C0C0C0", "wrong-length", "at most 8"),
        ("1F4E5205#3412E8030181", "not-single-frame", "tail byte 0x81"),
        ("1F4E527E#3412E8030181C0", "reserved-node-id", "reserved"),
        ("1F000105#C0", "unknown-type-id", "vendor range"),
        ("5F4E5205#3412E8030181C0", "not-extended-data-frame", "29-bit"),  # bit 30 set, not candump's error flag
    ],
)
def test_decode_errors_carry_the_line_number(tmp_path, capsys, line, reason, words):
    code, recs, _ = _decode(tmp_path, capsys, f"# header\n{MSG1_LINE}\n{line}\n{MSG1_LINE}\n")
    assert code == 1
    good1, bad, good2 = recs
    assert "error" not in good1 and "error" not in good2  # one bad line does not stop the rest
    assert bad["line"] == 3 and bad["reason"] == reason and words in bad["error"]
    assert bad["text"] == line
    assert set(bad) == {"error", "line", "reason", "frame", "text"}


def test_decode_error_names_the_frame_when_the_id_does(tmp_path, capsys):
    _, (rec,), _ = _decode(tmp_path, capsys, "1F4E5205#3412E803C0\n")
    assert rec["frame"] == "msg1" and rec["error"].startswith("msg1: ")


def test_undecodable_bytes_are_a_line_error_not_a_crash(tmp_path, capsys):
    code, recs, err = _decode(tmp_path, capsys, b"\xff\xfe\x00junk\n" + MSG1_LINE.encode() + b"\n")
    assert code == 1 and err == ""
    assert recs[0]["line"] == 1 and "error" in recs[0] and recs[1]["name"] == "msg1"


def test_decode_missing_file_is_a_usage_error(tmp_path, capsys):
    assert main(["decode", str(tmp_path / "nope.log")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot read" in err


def test_parser_agrees_with_python_can_canutils_reader(tmp_path):
    lines = [
        "(1700000000.123456) can0 1F4E5205#3412E8030181C0",
        "(1700000000.200000) vcan1 004E8500#23614589C7AB01C3 T",
        "(0.5) can0 123#1122",
        "(0.6) can0 1F4E5205#R",
        "(0.7) can0 10D68580#",
    ]
    log = tmp_path / "ref.log"
    log.write_text("\n".join(lines) + "\n")
    theirs = list(can.CanutilsLogReader(log))
    for line, ref in zip(lines, theirs):
        mine = parse_candump(line).msg
        assert mine.equals(ref, timestamp_delta=1e-9, check_channel=True, check_direction=True), (line, mine, ref)


# ---------------------------------------------------------------------------------------------------
# encode


def test_encode_worked_example(capsys):
    assert _encode(capsys, "msg1", "speed=0x1234", "pwm=1000", "status=0x8101", "--source", "5") == (0, "1F4E5205#3412E8030181C0", "")


def test_encode_throttle_list_and_defaults(capsys):
    code, out, err = _encode(capsys, "raw_command_12b", "channels=0x123,0x456,0x789,0xABC", "group=1")
    assert (code, out) == (0, "004E8500#23614589C7AB01C0")  # host node 0, HIGHEST, tid 0 (R4 vector)
    assert err.count("warning") == 1 and "channels[3]=2748" in err  # 0xABC is above the document's 2000 (R6)


@pytest.mark.parametrize(
    "argv",
    [
        ["msg1", "speed=100", "pwm=200", "status=0x0100", "--source", "7", "--transfer-id", "9"],
        ["msg2", "voltage=2520", "current=150", "temperature=41", "--source", "0x7D"],
        ["raw_command_14b", "channels=1000,1000,1000,1000"],
        ["raw_command_12b", "channels=1000,1100,1200,1300", "group=5", "--transfer-id", "31"],
        ["raw_command_10b", "channels=1,2,3,4,5,1000"],
        ["get_esc_id", "node_id=3", "throttle_channel=3", "--source", "3"],
        ["set_freq", "option=write", "msg1_interval=10", "msg2_interval=50", "msg3_interval=250", "--destination", "1"],
        ["214", "option=0", "--destination", "1", "--response", "--source", "1"],
        ["set_led", "option=1", "color=red+green", "blink=2", "--destination", "3", "--priority", "low"],
        ["msg_control", "command=suspend", "--priority", "8"],
        ["self_test", "--destination", "9"],
    ],
)
def test_encode_output_decodes_back_to_the_fields(tmp_path, capsys, argv):
    code, wire, err = _encode(capsys, *argv)
    assert code == 0 and err == "", err
    code, (rec,), _ = _decode(tmp_path, capsys, wire + "\n")
    assert code == 0, rec
    spec = BY_NAME[rec["name"]]
    assert str(spec.type_id) == argv[0] or spec.name == argv[0]
    given = dict(a.split("=", 1) for a in argv if "=" in a)
    for key, text in given.items():
        value = rec["fields"][key]
        if isinstance(value, list):
            assert value == [int(v, 0) for v in text.split(",")]
        elif text[0].isdigit():
            assert value == int(text, 0)
        else:  # a code or flag name
            decoded = rec["decoded"][key]
            assert decoded == text.replace("_", " ") or decoded == text.split("+") or sorted(decoded) == sorted(text.split("+"))
    opts = dict(zip(argv[::1], argv[1::1]))
    assert rec["source"] == int(opts.get("--source", "0"), 0)
    assert rec["transfer_id"] in (None, int(opts.get("--transfer-id", "0")))
    if "--destination" in opts:
        assert rec["destination"] == int(opts["--destination"])
        assert rec["kind"] == ("response" if "--response" in argv else "request")
    else:
        assert rec["destination"] is None and rec["kind"] == "message"


def test_encode_241_pair_round_trips_with_its_option_layout(tmp_path, capsys):
    _, request, _ = _encode(capsys, "maintenance_information", "option=2", "--destination", "4", "--transfer-id", "6")
    _, response, _ = _encode(
        capsys, "maintenance_information", "power_ups=12", "stops=11", "fault_code=0", "--response", "--source", "4", "--destination", "0", "--transfer-id", "6"
    )
    code, (_, resp), _ = _decode(tmp_path, capsys, f"{request}\n{response}\n")
    assert code == 0
    assert resp["fields"] == {"power_ups": 12, "stops": 11, "fault_code": 0, "option": 2}


def test_encode_illegal_value_warns_and_still_prints(capsys):
    code, out, err = _encode(capsys, "set_freq", "option=1", "msg1_interval=5", "msg2_interval=50", "msg3_interval=251", "--destination", "1")
    assert code == 0 and out == "10D68180#010532FBC0"
    lines = err.splitlines()
    assert len(lines) == 2
    assert "warning" in lines[0] and "msg1_interval=5" in lines[0] and "10..250" in lines[0] and "R10" in lines[0]
    assert "msg3_interval=251" in lines[1]


def test_encode_code_field_warning_lists_the_codes(capsys):
    code, out, err = _encode(capsys, "set_baud", "baud=7", "--destination", "1")
    assert code == 0 and out == "10D38180#07C0"
    assert "baud=7" in err and "6 (50000 bit/s)" in err


def test_encode_throttle_range_warnings(capsys):
    code, out, err = _encode(capsys, "raw_command_12b", "channels=3000,1000,1000,1000", "group=6")
    assert code == 0 and out.startswith("004E8500#")
    assert "channels[0]=3000" in err and "0..2000" in err and "R6" in err
    assert "group=6" in err and "1..5" in err


def test_encode_reserved_node_warning(capsys):
    code, out, err = _encode(capsys, "msg1", "speed=0", "pwm=0", "status=0", "--source", "126")
    assert code == 0 and out == "1F4E527E#000000000000C0"
    assert "126 is reserved" in err


@pytest.mark.parametrize(
    "argv, words",
    [
        (["nope"], "no frame 'nope'"),
        (["set_freq", "option=1"], "--destination"),
        (["msg1", "speed=70000", "pwm=0", "status=0"], "speed must be an integer in 0..65535"),
        (["msg1", "speed=1", "bogus=3", "pwm=0", "status=0"], "unknown field"),
        (["msg1", "speed"], "not key=value"),
        (["msg1", "speed=fast", "pwm=0", "status=0"], "not an integer"),
        (["msg1", "speed=1", "speed=2"], "given twice"),
        (["msg1", "pwm=0", "status=0"], "speed is required"),
        (["raw_command_12b", "channels=1000", "group=1"], "exactly 4 channels"),
        (["raw_command_14b", "channels=1000,1000,1000,20000"], "0..16383"),
        (["msg1", "speed=0", "pwm=0", "status=0", "--transfer-id", "32"], "transfer id"),
        (["msg1", "speed=0", "pwm=0", "status=0", "--source", "128"], "source node id"),
        (["msg1", "speed=0", "pwm=0", "status=0", "--response"], "not a response"),
        (["msg1", "speed=0", "pwm=0", "status=0", "--destination", "3"], "broadcast"),
        (["msg1", "--priority", "urgent"], "not a priority"),
        (["msg1", "--source", "x"], "not an integer"),
        (["expand_set_part", "set_cmd=0xFFF0", "part=1", "--destination", "1", "--response"], "no response"),
    ],
)
def test_encode_errors_are_one_line_exit_2(capsys, argv, words):
    code = main(["encode", *argv])
    out, err = capsys.readouterr()
    assert code == 2
    assert out == ""
    assert err.count("\n") == 1 and "error" in err and words in err, err


def test_help_and_version_exit_0(capsys):
    assert main(["--version"]) == 0
    assert main(["encode", "--help"]) == 0
    assert "KEY=VALUE" in capsys.readouterr().out


# ---------------------------------------------------------------------------------------------------
# frames, main


def test_frames_lists_the_catalogue(capsys):
    assert main(["frames"]) == 0
    out = capsys.readouterr().out
    for spec in CATALOGUE:
        assert spec.name in out and spec.title in out
    assert main(["frames", "--json"]) == 0
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [r["name"] for r in rows] == [s.name for s in CATALOGUE]
    assert rows[0] == {"id": 20000, "name": "can_test", "kind": "message", "priority": 31, "priority_name": "LOWEST", "section": "4.4.1", "title": "CAN Test"}


def test_no_command_prints_help_and_exits_2(capsys):
    assert main([]) == 2
    assert "decode" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------------
# the installed script, for real


def test_installed_script_encode_pipes_into_decode():
    ckesc = _script()
    enc = subprocess.run([ckesc, "encode", "set_freq", "option=1", "msg1_interval=5", "--destination", "3"], capture_output=True, text=True, timeout=60)
    assert enc.returncode == 0 and "msg1_interval=5" in enc.stderr
    dec = subprocess.run([ckesc, "decode"], input=enc.stdout + "garbage\n", capture_output=True, text=True, timeout=60)
    assert dec.returncode == 1 and dec.stderr == ""
    good, bad = (json.loads(line) for line in dec.stdout.splitlines())
    assert good["fields"]["msg1_interval"] == 5 and good["destination"] == 3
    assert bad == {"error": "not a candump line: 'garbage'", "line": 2, "reason": "not-candump", "frame": None, "text": "garbage"}


def test_installed_script_survives_a_closed_pipe(tmp_path):
    ckesc = _script()
    log = tmp_path / "big.log"
    log.write_text("".join(f"({1700000000 + i / 1000:.6f}) can0 1F4E5205#3412E8030181C{i % 10}\n" for i in range(50_000)))
    proc = subprocess.Popen([ckesc, "decode", str(log)], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = proc.stdout.readline()  # `| head -1`
    proc.stdout.close()
    _, err = proc.communicate(timeout=60)
    assert json.loads(first)["line"] == 1
    assert b"Traceback" not in err and err == b""
    assert proc.returncode == 141


def _run_args(*argv: str):
    """``ckesc run ARGV``'s namespace as its handler sees it (selection and pytest's arguments split at ``--``)."""
    from ckesc.cli import build_parser

    args = build_parser().parse_args(["run", *argv])
    args.selection, args.pytest_args = args.free, args.after_dashes
    return args


def test_run_passes_the_trace_format_to_the_plugin():
    from ckesc.run import pytest_argv

    argv = pytest_argv(_run_args("--trace-format", "asc"))
    assert argv[argv.index("--ckesc-trace-format") + 1] == "asc"
    default = pytest_argv(_run_args())
    assert default[default.index("--ckesc-trace-format") + 1] == "blf"
    assert main(["run", "--trace-format", "pcap"]) == 2


def test_run_splits_at_the_first_dashes_its_own_before_pytests_after_untouched():
    """Before the first ``--``: ckesc run's options (also after a section) and the selection; after it: pytest's
    arguments as given, a section number among them an option's value (``-k 4.4``), ckesc run's own flags pytest's."""
    from ckesc.run import pytest_argv

    args = _run_args("-q", "4.4.22", "--strict", "4.4.3", "--", "-k", "4.4", "--maxfail", "3", "-x", "--strict", "--",
                     "--junitxml=out/j.xml")
    assert args.ckesc_strict and args.quiet
    assert args.selection == ["4.4.22", "4.4.3"]
    assert args.pytest_args == ["-k", "4.4", "--maxfail", "3", "-x", "--strict", "--", "--junitxml=out/j.xml"]
    argv = pytest_argv(_run_args("4.4.22", "--", "--no-header"))
    assert argv[0].endswith("conformance/test_s4_4_22_set_freq.py") and argv[-1] == "--no-header"


def test_run_names_the_way_out_for_pytest_options_before_the_dashes(capsys):
    assert main(["run", "4.4.18", "-k", "just_inside"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["ckesc run: error: -k is not an option of ckesc run: pytest's options go after `--` (ckesc run 4.4.18 "
                   "-- -k just_inside)"]


def test_run_refuses_a_selection_after_the_dashes_and_says_where_it_goes(tmp_path):
    """``ckesc run -- --no-header 4.4.22``: pytest's own parser reads ``4.4.22`` as a path to collect, not as an
    option's value; that is one line and exit 2 naming the way out (not pytest's "file not found"), no report."""
    done = subprocess.run([sys.executable, "-m", "ckesc", "run", "--reports", str(tmp_path / "r"), "--", "--no-header",
                           "4.4.22"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stdout[-2000:] + done.stderr
    assert done.stderr.strip().splitlines() == [
        "ckesc run: error: 4.4.22 after `--` would be a path for pytest to collect: the selection goes before `--` "
        "(ckesc run 4.4.22 -- --no-header)"]
    assert not (tmp_path / "r").exists()


def test_run_selects_before_the_dashes_and_hands_pytest_what_follows(tmp_path):
    """``ckesc run 4.4.22 -- --no-header``: the section's tests only, and pytest's header left out as asked."""
    done = subprocess.run([sys.executable, "-m", "ckesc", "run", "--reports", str(tmp_path), "--trace-format", "none",
                           "4.4.22", "--", "--no-header", "-k", "read_answers"], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    assert "platform " not in done.stdout and "rootdir:" not in done.stdout, done.stdout[:2000]
    doc = json.loads(next(tmp_path.glob("*/results.json")).read_text())
    assert {r["nodeid"].split("::")[0] for r in doc["results"]} == {"conformance/test_s4_4_22_set_freq.py"}




def test_a_section_of_several_modules_selects_them_all():
    """``ckesc run robustness``: R17's module and R18's, not whichever module the glob met last."""
    from ckesc.run import resolve_selection

    picked = [Path(p).name for p in resolve_selection(["robustness"])]
    assert picked == sorted(p.name for p in (Path(conformance.__file__).parent).glob("test_robustness_*.py"))
    assert len(picked) >= 2
