"""Rig files (issue #13): the schema, what each bench becomes on the command line, and ``ckesc run --rig``'s
set-up mistakes (exit 2, one line naming the file, the bench and the key, no report directory)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from procs import CKESC
from procs import env as _env

from ckesc.rigs import rig as rigs

EXAMPLE = Path(__file__).resolve().parents[2] / "fixtures" / "rigs" / "example.toml"


def _error(text: str, path: str = "lab/rig.toml") -> str:
    with pytest.raises(rigs.RigError) as exc:
        rigs.parse(text, path)
    return str(exc.value)


def test_the_example_rig_loads_and_each_bench_is_a_ckesc_run_command_line():
    rig = rigs.load(EXAMPLE)
    assert list(rig.benches) == ["sim-a", "sim-b", "realtime-c"]
    assert rig.benches["sim-a"].argv() == ["--dut", "emulator", "--lane", "simulated", "--nodes", "1", "--profile", "emulator"]
    assert rig.benches["sim-b"].argv() == ["--dut", "emulator", "--lane", "simulated", "--nodes", "1", "--emulator-seed", "7",
                                           "--emulator-option", "report_timer=grid", "--emulator-option", "report_delay=0.4"]
    assert rig.benches["realtime-c"].options()["lane"] == "realtime"
    assert [b.name for b in rig.select(["realtime-c", "sim-a"])] == ["realtime-c", "sim-a"]


def test_a_bus_bench_passes_every_bus_argument_and_its_power():
    rig = rigs.parse("""
[bench.esc-17]
bus = { interface = "socketcand", host = "127.0.0.1", port = 29536, channel = "can0", bitrate = 1000000, fd = false }
profile = "../duts/vendor-x.toml"
node_id = 5
power = { command = { off = "relay 3 off", on = "relay 3 on" } }
bitrate_cmd = "set-bitrate {bitrate}"
host_send_error_ms = 3
allow_motor_spin = true
""", "/lab/rigs/line.toml")
    assert rig.benches["esc-17"].argv() == [
        "--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0", "--can-bitrate", "1000000",
        "--can-config", "host=127.0.0.1", "--can-config", "port=29536", "--can-config", "fd=false",
        "--profile", "/lab/rigs/../duts/vendor-x.toml", "--node-id", "5", "--power", "command",
        "--power-off-cmd", "relay 3 off", "--power-on-cmd", "relay 3 on", "--can-bitrate-cmd", "set-bitrate {bitrate}",
        "--host-send-error", "3.0", "--allow-motor-spin"]


def test_labgrid_power_and_place_become_the_labgrid_options():
    rig = rigs.parse("""
[bench.remote]
bus = { interface = "socketcand", host = "lab2", port = 29536, channel = "can0" }
power = { labgrid = { env = "lab2.yaml", target = "esc-bench" } }
place = "lab2-esc"
""", "/lab/rigs/line.toml")
    opts = rig.benches["remote"].options()
    assert opts["power"] == "labgrid" and opts["labgrid_env"] == "/lab/rigs/lab2.yaml"
    assert opts["labgrid_target"] == "esc-bench" and opts["labgrid_place"] == "lab2-esc"
    assert rig.benches["remote"].argv()[-6:] == ["--labgrid-env", "/lab/rigs/lab2.yaml", "--labgrid-target", "esc-bench",
                                                 "--labgrid-place", "lab2-esc"]


def test_the_rig_keys_of_the_option_table_are_the_rig_files_and_its_benches_set_just_those():
    """The run option table (session/options.py) names the rig file key that sets each bench option: each names a
    key of the schema, and a bench sets rig options only (so ``ckesc run --rig`` refuses each of them given)."""
    from ckesc.session.options import BENCH_OPTIONS, BY_DEST

    schema = set(rigs._BenchDoc.model_fields)
    assert {BY_DEST[d].rig.split(".")[0] for d in BENCH_OPTIONS} <= schema
    rig = rigs.parse("""
[bench.bus]
bus = { interface = "socketcand", channel = "can0", bitrate = 500000, host = "h" }
node_id = 5
power = { labgrid = { env = "lab.yaml", target = "t" } }
place = "p"
bitrate_cmd = "b {bitrate}"
host_send_error_ms = 3
allow_motor_spin = true
profile = "x"
firmware = "esc.bin"
flash_cmd = "labgrid"
flash_timeout = 60
expect_firmware = { firmware_date = "2024-10-11" }
[bench.emu]
lane = "realtime"
power = "emulator"
emulator = { nodes = [1, 2], faults = ["answer_late"], seed = 3, options = { boot_time = 0.2 }, variants = 4 }
""", "/lab/rig.toml")
    for bench in rig.benches.values():
        assert set(bench.options()) <= set(BENCH_OPTIONS), bench.name
    assert set(BENCH_OPTIONS) - {d for b in rig.benches.values() for d in b.options()} <= {"power_off_cmd", "power_on_cmd"}


@pytest.mark.parametrize("text, expected", [
    ("[bench.a]\nprofil = 'x'\n", "lab/rig.toml: [bench.a] unknown key 'profil' (known: description, dut, lane, bus, profile"),
    ("[bench.a]\nprofil = 'x'\n", "did you mean 'profile'?"),
    ("[benches.a]\n", "lab/rig.toml: unknown section 'benches' (known: rig, bench); did you mean 'bench'?"),
    ("[bench.a]\nbus = { interface = 'virtual' }\npower = { command = { of = 'x', on = 'y' } }\n",
     "lab/rig.toml: [bench.a] power.command: unknown key 'of' (known: off, on); did you mean 'off'?"),
    ("[bench.a]\nemulator = { nodez = [1] }\n", "[bench.a] emulator: unknown key 'nodez'"),
    ("[bench.a]\nbus = { interface = 'virtual' }\npower = 'manaul'\n", "[bench.a] power = 'manaul': power 'manaul': one of"),
    ("[bench.a]\nbus = { interface = 'virtual' }\npower = {}\n", "[bench.a] power: a power table has exactly one of"),
    ("[bench.a]\nbus = { channel = 'can0' }\n", "[bench.a] bus.interface: missing"),
    ("[bench.a]\nbus = { interface = 'x', filters = [1] }\n", "bus argument 'filters' must be a plain value"),
    ("[bench.a]\nnode_id = 126\n", "[bench.a] node_id = 126: input should be less than or equal to 125"),
    ("[bench.a]\nnode_id = '5'\n", "[bench.a] node_id = '5': input should be a valid integer"),
    ("[bench.a]\npower = 'none'\n", "dut = 'emulator' switches its emulator's power itself"),
    ("[bench.a]\nbus = { interface = 'x' }\npower = 'emulator'\n", "power 'emulator' is the emulator's own switch"),
    ("[bench.a]\nbus = { interface = 'x' }\nplace = 'p'\n", "place (a labgrid place) needs power = { labgrid"),
    ("[bench.'a b']\n", "bench name 'a b': letters, digits"),
    ("[rig]\ndescription = 'x'\n", "lab/rig.toml: bench: missing"),
    ("[bench.a\n", "lab/rig.toml: not valid TOML"),
])
def test_a_mistake_in_a_rig_names_the_file_the_bench_and_the_key(text, expected):
    assert expected in _error(text)


def test_an_unknown_bench_is_named_with_the_benches_there_are():
    with pytest.raises(rigs.RigError, match=r"no bench 'sim-x' \(benches: sim-a, sim-b, realtime-c\); did you mean"):
        rigs.load(EXAMPLE).select(["sim-x"])


def _run(tmp: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*CKESC, "run", "--reports", str(tmp / "reports"), *args], cwd=tmp, env=_env(tmp),
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("rig, args, expected", [
    ("[bench.a]\nlane = 'simulated'\nprofle = 'emulator'\n", [], "rig.toml: [bench.a] unknown key 'profle'"),
    ("[bench.a]\nprofile = 'no-such-profile'\n", [], "bench a: no DUT profile 'no-such-profile'"),
    ("[bench.a]\nemulator = { faults = ['no_such_fault'] }\n", [], "bench a: --emulator-faults: unknown fault 'no_such_fault'"),
    ("[bench.a]\nbus = { interface = 'virtual', channel = 'x' }\npower = 'manual'\n", [],
     "bench a: power 'manual' prompts an operator at the console, which a batch cannot; run that bench alone: ckesc run --dut bus"),
    ("[bench.a]\nbus = { interface = 'virtual' }\npower = { command = { off = 'no-such-relay off', on = 'x' } }\n", [],
     "bench a: --power-off-cmd: program 'no-such-relay' not found on PATH"),
    ("[bench.a]\n", ["--benches", "b"], "no bench 'b' (benches: a)"),
    ("[bench.a]\n", ["--dut", "bus"], "--dut is set per bench in the rig file"),
    ("[bench.a]\n", ["4.9.9"], "no conformance section '4.9.9'"),
])
def test_a_set_up_mistake_of_a_batch_is_one_line_exit_2_and_no_report(tmp_path, rig, args, expected):
    (tmp_path / "rig.toml").write_text(rig)
    done = _run(tmp_path, "--rig", "rig.toml", *args)
    assert done.returncode == 2, done.stdout + done.stderr
    assert expected in done.stderr and done.stderr.startswith("ckesc run: error: "), done.stderr
    assert len(done.stderr.strip().splitlines()) == 1, done.stderr
    assert not (tmp_path / "reports").exists() or not any((tmp_path / "reports").iterdir())


def test_benches_without_a_rig_is_a_usage_error(tmp_path):
    done = _run(tmp_path, "--benches", "a")
    assert done.returncode == 2 and "--benches chooses benches of a rig: it needs --rig FILE" in done.stderr
