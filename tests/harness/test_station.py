"""One way to build a bench from options (issue #28 item 5): the plain-data ``BenchOptions`` made from the option
rows, the one builder (``ckesc/bench/station.py``) that the pytest plugin, ``ckesc explore`` and ``ckesc profile``
call alike, and no command imitating a pytest object to reach it (~5 s).

What the builder's preflight catches, every command now catches the same way: a stale socketcand port is one line
and exit 2 within seconds for ``ckesc explore`` and ``ckesc profile check`` as for ``ckesc run`` (the explorer used
to wait on python-can's client, which retries for ever), and so is a node id no ESC can have."""

from __future__ import annotations

import ast
import dataclasses
import socket
import subprocess
import time
from pathlib import Path

import pytest
from procs import CKESC
from procs import env as _env

from ckesc.bench.station import BENCH_ROWS, BenchOptions, Station, build
from ckesc.session import options

ROOT = Path(__file__).resolve().parents[2]
#: the layers that hold a real pytest object: the plugin and the conformance modules (pytest hands them theirs)
PYTEST_LAYERS = ("ckesc/session/", "conformance/")


def test_bench_options_are_the_bench_rows_of_the_one_option_table():
    """An option is declared once: its row; the run's table lists the bench's rows, BenchOptions has one field each."""
    assert [f.name for f in dataclasses.fields(BenchOptions)] == [o.dest for o in BENCH_ROWS]
    assert [o for o in options.OPTIONS if o in BENCH_ROWS] == list(BENCH_ROWS)
    assert options.bench_options() == BENCH_ROWS
    defaults = BenchOptions.of({}.get)
    assert defaults == BenchOptions() and defaults.dut == "emulator" and defaults.can_config == ()
    given = BenchOptions.of({"dut": "bus", "can_config": ["port=1"], "emulator_seed": None}.get)
    assert given.dut == "bus" and given.can_config == ("port=1",) and given.emulator_seed == 0
    with pytest.raises(dataclasses.FrozenInstanceError):
        given.dut = "emulator"  # type: ignore[misc]


def test_the_builder_gives_the_emulated_profile_its_variant_and_the_lanes():
    station = build(BenchOptions(emulator_option=("report_jitter_s=0.003",)))
    try:
        assert isinstance(station, Station) and station.power is None
        assert station.profile.jitter_s >= 0.003, "what the emulated ESC's variant declares, its vendor would state"
        lane = station.open_lane()
        assert station.open_lane() is lane and lane.clock == "simulated"
        assert station.prove(cycles_power=True) == [], "the proof is a real bus's"
    finally:
        station.close()
    assert station.lane is None
    station.close()  # idempotent


def _classes_and_calls(path: Path) -> tuple[list[str], list[int]]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    fakes = [f"{node.name} (line {node.lineno})" for node in ast.walk(tree) if isinstance(node, ast.ClassDef)
             and any(isinstance(b, ast.FunctionDef) and b.name in ("getoption", "getini", "addinivalue_line")
                     for b in node.body)]
    calls = [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Attribute) and node.attr == "getoption"]
    return fakes, calls


def test_no_command_imitates_a_pytest_object_to_reach_a_bench():
    """``config.getoption`` only where pytest hands over a real config; no class anywhere plays one."""
    found = []
    for path in sorted([*ROOT.glob("ckesc/**/*.py"), *ROOT.glob("conformance/**/*.py"), *ROOT.glob("bench/*.py")]):
        where = path.relative_to(ROOT).as_posix()
        fakes, calls = _classes_and_calls(path)
        found += [f"{where}: class {f} imitates a pytest Config" for f in fakes]
        if calls and not where.startswith(PYTEST_LAYERS):
            found.append(f"{where}: getoption at line(s) {calls}")
    assert not found, "\n".join(found)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.mark.parametrize("command", [("explore", "--budget", "10s", "-q", "--database", "none"), ("profile", "check")])
def test_every_command_takes_the_bench_preflight(tmp_path, command):
    """A stale socketcand port and a node id no ESC can have: one line, exit 2, in seconds, from each command."""
    port = _free_port()
    bus = ["--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0", "--can-config", "host=127.0.0.1",
           "--can-config", f"port={port}", "--bus-open-timeout", "1"]
    start = time.monotonic()
    done = subprocess.run([*CKESC, *command, *bus], cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True,
                          timeout=60)
    took = time.monotonic() - start
    assert done.returncode == 2, done.stdout + done.stderr
    assert "cannot open the CAN bus (interface=socketcand, channel=can0, host=127.0.0.1, " \
           f"port={port}): 127.0.0.1:{port}: nobody listens there (connection refused)" in done.stderr, done.stderr
    assert "Traceback" not in done.stderr and took < 10, f"{took:.1f} s"
    done = subprocess.run([*CKESC, *command, "--dut", "bus", "--can-interface", "virtual", "--node-id", "126"],
                          cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and "--node-id 126 is out of range" in done.stderr, done.stdout + done.stderr
