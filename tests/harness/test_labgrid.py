"""labgrid power and shared places (issue #13, items 3 and 4), for real on this machine: ``ckesc emulate`` behind
socketcand is the DUT, a small HTTP relay (labgrid's ``simplerest`` power model) switches its power, and a real
``labgrid-coordinator`` and ``labgrid-exporter`` on 127.0.0.1 share it as a place. ``ckesc run --power labgrid``
cycles the DUT's power through labgrid's NetworkPowerDriver (proven by the power-up counter), acquires the place
first and releases it on every way out; a place someone else holds is refused with who holds it.

Without labgrid (the ``rig`` extra) these tests skip and say so; they never fail for it."""

from __future__ import annotations

import importlib.util
import json
import os
import shutil
import signal
import subprocess
import sys
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
from procs import CKESC, Emulator
from procs import env as _env

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

HAVE_LABGRID = importlib.util.find_spec("labgrid") is not None
needs_labgrid = pytest.mark.skipif(not HAVE_LABGRID, reason='labgrid is not installed (pip install -e ".[rig]")')
needs_lab = pytest.mark.skipif(not (HAVE_LABGRID and shutil.which("labgrid-coordinator") and shutil.which("labgrid-exporter")),
                               reason='labgrid-coordinator / labgrid-exporter not found (pip install -e ".[rig]")')

#: a quick power-cycling test: 4.4.27's power-up counter, cycled through the power control and proven by it
POWER_CYCLE_TEST = "power_up_counter_counts_each_power_up"


def _ckesc(tmp: Path, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([*CKESC, *args], cwd=tmp, env=_env(tmp), capture_output=True, text=True, timeout=timeout)


def _profile(tmp: Path, off_s: float = 0.5) -> Path:
    profile = tmp / "bench.toml"
    profile.write_text('[dut]\nname = "bench"\n[capabilities]\nled = true\nmotor = true\n'
                       f"[timing]\nerror_s = 0.002\nboot_s = 0.5\noff_s = {off_s}\n")
    return profile


def _bus_args(tmp: Path, can_port: int, off_s: float = 0.5) -> list[str]:
    return ["--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0", "--can-config", "host=127.0.0.1",
            "--can-config", f"port={can_port}", "--profile", str(_profile(tmp, off_s)), "--reports", str(tmp / "reports")]


def _results(tmp: Path) -> dict:
    return json.loads((tmp / "reports" / "latest" / "results.json").read_text())


def _env_file(tmp: Path, resource: str) -> Path:
    """A labgrid environment file: target ``esc`` with ``resource`` (YAML lines) and labgrid's NetworkPowerDriver."""
    path = tmp / "env.yaml"
    path.write_text(f"targets:\n  esc:\n    resources:\n{resource}    drivers:\n      NetworkPowerDriver: {{}}\n")
    return path


@pytest.fixture
def bench(tmp_path):
    """The DUT (``ckesc emulate``) and the HTTP power switch in front of it."""
    pytest.importorskip("requests", reason="labgrid's REST power models need requests (comes with labgrid)")
    from labgrid_lab import PowerSwitch

    emu = Emulator(tmp_path)
    switch = PowerSwitch(emu.control)
    yield emu, switch
    switch.close()
    emu.close()


@pytest.fixture
def lab(tmp_path, bench):
    """A labgrid coordinator and exporter sharing the bench's power switch as place ``rig1``."""
    from labgrid_lab import Lab

    where = tmp_path / "lab"
    where.mkdir()
    lab = Lab(where, bench[1].url, _env(tmp_path))
    try:
        lab.place("rig1")
        yield lab
    finally:
        lab.close()


# ----------------------------------------------------------------------------------------- labgrid power, local
@needs_labgrid
def test_labgrid_power_without_a_coordinator_cycles_the_dut(tmp_path, bench):
    """--power labgrid with a local NetworkPowerPort: labgrid's driver switches the relay, the counter proves it."""
    emu, switch = bench
    env_file = _env_file(tmp_path, f"      NetworkPowerPort:\n        model: simplerest\n        host: '{switch.url}'\n"
                                   "        index: 0\n")
    done = _ckesc(tmp_path, "run", *_bus_args(tmp_path, emu.port), "--power", "labgrid", "--labgrid-env", str(env_file),
                  "--labgrid-target", "esc", "--", "-k", POWER_CYCLE_TEST)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    doc = _results(tmp_path)
    assert [r["outcome"] for r in doc["results"]] == ["PASS"], doc["results"]
    assert doc["info"]["power"] == "labgrid" and "NetworkPowerDriver of target esc" in doc["info"]["power_labgrid"]
    assert switch.switched[:2] == ["off", "on"] and len(switch.switched) % 2 == 0, switch.switched


LABGRID_MISTAKES = [
    pytest.param([], None, ["--power labgrid needs --labgrid-env"], id="no-env"),
    pytest.param(["--labgrid-env", "nowhere.yaml"], None, ["--labgrid-env nowhere.yaml: no such file"], id="env-missing"),
    pytest.param(["--labgrid-env", "env.yaml", "--labgrid-target", "other"], "", ["no target 'other'", "esc"],
                 id="target-missing"),
    pytest.param(["--labgrid-env", "env.yaml"], "nodriver", ["target esc of env.yaml has no power driver"], id="no-driver"),
    pytest.param(["--labgrid-env", "env.yaml"], "garbage", ["--labgrid-env env.yaml: not a labgrid environment file"],
                 id="not-yaml"),
    pytest.param(["--labgrid-env", "env.yaml", "--labgrid-place", "rig9", "--labgrid-coordinator", "127.0.0.1:1"], "",
                 ["--labgrid-place rig9: cannot reach the labgrid coordinator at 127.0.0.1:1"], id="no-coordinator"),
]


@needs_labgrid
@pytest.mark.parametrize("args, env_kind, expect", LABGRID_MISTAKES)
def test_a_labgrid_setup_mistake_is_one_line_exit_2(tmp_path, args, env_kind, expect):
    port = "      NetworkPowerPort:\n        model: simplerest\n        host: 'http://127.0.0.1:1/{index}/{value}'\n        index: 0\n"
    if env_kind == "":
        _env_file(tmp_path, port)
    elif env_kind == "nodriver":
        (tmp_path / "env.yaml").write_text(f"targets:\n  esc:\n    resources:\n{port}")
    elif env_kind == "garbage":
        (tmp_path / "env.yaml").write_text("targets: [esc\n")
    done = _ckesc(tmp_path, "run", "-q", "--dut", "bus", "--can-interface", "virtual", "--power", "labgrid",
                  "--reports", str(tmp_path / "reports"), *args, timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, done.stderr
    for text in expect:
        assert text in lines[0], lines[0]
    assert not (tmp_path / "reports" / "latest").exists()


def test_without_labgrid_the_error_names_the_extra(tmp_path):
    """labgrid not installed (here: hidden from the import system, as if it were absent): one line naming the extra."""
    (tmp_path / "env.yaml").write_text("targets: {}\n")
    code = ("import sys\n"
            "class Absent:\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            "        if name.split('.')[0] == 'labgrid':\n"
            "            raise ModuleNotFoundError(f'No module named {name!r}', name=name)\n"
            "sys.meta_path.insert(0, Absent())\n"
            "from ckesc.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    done = subprocess.run([sys.executable, "-c", code, "run", "-q", "--dut", "bus", "--can-interface", "virtual", "--power",
                           "labgrid", "--labgrid-env", "env.yaml", "--reports", str(tmp_path / "reports")],
                          cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "needs labgrid" in lines[0] and 'pip install ".[rig]"' in lines[0], done.stderr


def test_labgrid_options_need_power_labgrid(tmp_path):
    done = _ckesc(tmp_path, "run", "-q", "--dut", "bus", "--can-interface", "virtual", "--labgrid-place", "rig1",
                  "--reports", str(tmp_path / "reports"), timeout=120)
    assert done.returncode == 2 and "--labgrid-place is for --power labgrid" in done.stderr, done.stderr


# ----------------------------------------------------------------------------------------- shared places
def _place_env(tmp: Path, name: str = "rig1") -> Path:
    return _env_file(tmp, f"      RemotePlace:\n        name: {name}\n")


@needs_lab
def test_a_shared_place_is_acquired_cycled_through_labgrid_and_released(tmp_path, bench, lab):
    emu, switch = bench
    done = _ckesc(tmp_path, "run", *_bus_args(tmp_path, emu.port), "--power", "labgrid", "--labgrid-env",
                  str(_place_env(tmp_path)), "--labgrid-coordinator", lab.address, "--", "-k", POWER_CYCLE_TEST)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    doc = _results(tmp_path)
    assert [r["outcome"] for r in doc["results"]] == ["PASS"], doc["results"]
    assert "on place rig1" in doc["info"]["power_labgrid"], doc["info"]
    junit = ET.parse(tmp_path / "reports" / "latest" / "junit.xml").getroot()
    props = {p.get("name"): p.get("value") for p in junit.find("testsuite").find("properties")}
    assert props["power"] == "labgrid" and props["power_labgrid"] == doc["info"]["power_labgrid"]
    assert switch.switched[:2] == ["off", "on"], switch.switched
    assert lab.holder("rig1") is None  # released
    assert "acquired place" not in done.stdout  # labgrid's own chatter stays out of the run's output


@needs_lab
def test_a_place_locked_by_someone_else_is_refused_with_who_holds_it(tmp_path, bench, lab):
    emu, switch = bench
    taken = lab.client("-p", "rig1", "acquire", user="alice")
    assert taken.returncode == 0, taken.stderr
    holder = lab.holder("rig1")
    assert holder and holder.endswith("/alice")
    done = _ckesc(tmp_path, "run", "-q", *_bus_args(tmp_path, emu.port), "--power", "labgrid", "--labgrid-env",
                  str(_place_env(tmp_path)), "--labgrid-place", "rig1", "--labgrid-coordinator", lab.address, timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and f"labgrid place rig1 is locked by {holder}" in lines[0], done.stderr
    assert lab.holder("rig1") == holder and switch.switched == []  # theirs still, and their DUT untouched
    assert not (tmp_path / "reports" / "latest").exists()


PLACE_MISTAKES = [
    pytest.param("rig1", ["--labgrid-place", "rig2"], ["--labgrid-place rig2, but target esc of", "is on place rig1"],
                 id="other-place"),
    pytest.param("rig7", [], ["--labgrid-place rig7: no such place on the coordinator", "places: rig1"], id="no-such-place"),
    pytest.param("rig1", ["--mine"], ["labgrid place rig1 is already acquired by you", "labgrid-client -p rig1 release"],
                 id="held-by-me"),
]


@needs_lab
@pytest.mark.parametrize("place, args, expect", PLACE_MISTAKES)
def test_a_place_mistake_is_one_line_exit_2(tmp_path, bench, lab, place, args, expect):
    emu, switch = bench
    if "--mine" in args:  # as this user on this host, outside the run (a leftover acquire)
        args = []
        assert lab.client("-p", "rig1", "acquire").returncode == 0
    done = _ckesc(tmp_path, "run", "-q", *_bus_args(tmp_path, emu.port), "--power", "labgrid", "--labgrid-env",
                  str(_place_env(tmp_path, place)), "--labgrid-coordinator", lab.address, *args, timeout=120)
    assert done.returncode == 2, done.stdout + done.stderr
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, done.stderr
    for text in expect:
        assert text in lines[0], lines[0]
    assert switch.switched == []


@needs_lab
def test_a_place_only_locks_a_bench_whose_power_is_reached_directly(tmp_path, bench, lab):
    """--labgrid-place with a target that has its own NetworkPowerPort (no RemotePlace): the place is held for the
    run and released after; the power goes through the target's own port."""
    emu, switch = bench
    env_file = _env_file(tmp_path, f"      NetworkPowerPort:\n        model: simplerest\n        host: '{switch.url}'\n"
                                   "        index: 0\n")
    done = _ckesc(tmp_path, "run", *_bus_args(tmp_path, emu.port), "--power", "labgrid", "--labgrid-env", str(env_file),
                  "--labgrid-place", "rig1", "--labgrid-coordinator", lab.address, "--", "-k", POWER_CYCLE_TEST)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    doc = _results(tmp_path)
    assert [r["outcome"] for r in doc["results"]] == ["PASS"] and "on place rig1" in doc["info"]["power_labgrid"]
    assert switch.switched[:2] == ["off", "on"] and lab.holder("rig1") is None


@needs_lab
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_run_releases_the_place(tmp_path, bench, lab, sig):
    """Ctrl-C (SIGINT to the process group) or SIGTERM mid-run: the run stops (exit 130) and the place is free.
    (Between tests that do not switch the power: an interruption while the DUT is off is another matter.)"""
    emu, _ = bench
    proc = subprocess.Popen([*CKESC, "run", *_bus_args(tmp_path, emu.port), "--power", "labgrid", "--labgrid-env",
                             str(_place_env(tmp_path)), "--labgrid-coordinator", lab.address, "4.4.4", "--", "-k",
                             "not power_up"],
                            cwd=tmp_path, env=_env(tmp_path), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    out = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:
            out.append(line)
            if "PASSED" in line:
                break
        held = lab.holder("rig1")
        if sig == signal.SIGINT:
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        rest, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    text = "".join(out) + rest
    assert held and "/" in held, ("the place was not acquired during the run", held, text[-2000:])
    assert proc.returncode == 130, text[-3000:]
    assert lab.holder("rig1") is None, text[-2000:]
    assert "Traceback" not in text, text[-3000:]


@needs_lab
def test_a_run_interrupted_while_the_dut_is_off_releases_the_place(tmp_path, bench, lab):
    """Ctrl-C while labgrid holds the DUT's power off (mid power cycle): the run ends INTERRUPTED (exit 130), says the
    settings it could not restore on a DUT that is off, and releases the place on the way out."""
    emu, switch = bench
    # a long off time (3 s): the switch says "off" while the run may still be inside labgrid's call, where an
    # interrupt may be taken up by the RPC; the Ctrl-C comes 0.3 s later, well inside the run's wait for the DUT
    proc = subprocess.Popen([*CKESC, "run", *_bus_args(tmp_path, emu.port, off_s=3.0), "--power", "labgrid",
                             "--labgrid-env", str(_place_env(tmp_path)), "--labgrid-coordinator", lab.address, "4.4.27",
                             "--", "-k", POWER_CYCLE_TEST], cwd=tmp_path, env=_env(tmp_path), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        # the second "off": the first is the bench proof's, before any test (issue #29)
        while switch.switched.count("off") < 2 or switch.switched[-1:] != ["off"]:
            assert proc.poll() is None and time.monotonic() < deadline, "the run never switched the power off"
            time.sleep(0.01)
        time.sleep(0.3)
        assert switch.switched[-1:] == ["off"], switch.switched
        os.killpg(proc.pid, signal.SIGINT)
        text, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, text[-3000:]  # INTERRUPTED, reports written: no traceback from the teardown
    assert "Traceback" not in text and "INTERRUPTED" in text, text[-3000:]
    assert "settings were not restored" in text, text[-3000:]  # the DUT was off: said, not raised
    assert lab.holder("rig1") is None, text[-2000:]


# ----------------------------------------------------------------------------------------- a rig with a shared place
@needs_lab
def test_a_rig_bench_on_a_shared_place_is_acquired_cycled_and_released_beside_a_simulated_bench(tmp_path, bench, lab):
    """``ckesc run --rig``: a bench that is labgrid place rig1 (its CAN over socketcand, its power through labgrid),
    beside a simulated bench. The place's bench is acquired in its own worker, its power cycled through labgrid and
    proven, the place released; both benches PASS; a second batch while someone else holds the place reports that
    bench ABSENT with who holds it, and the simulated bench still passes."""
    emu, switch = bench
    _profile(tmp_path)
    _place_env(tmp_path)
    (tmp_path / "rig.toml").write_text(
        "[bench.shared]\n"
        f'bus = {{ interface = "socketcand", host = "127.0.0.1", port = {emu.port}, channel = "can0" }}\n'
        'profile = "bench.toml"\n'
        'power = { labgrid = { env = "env.yaml", target = "esc" } }\n'
        'place = "rig1"\n\n'
        "[bench.sim]\n")
    env = {**_env(tmp_path), "LG_COORDINATOR": lab.address}

    def batch(reports: str) -> tuple[subprocess.CompletedProcess, dict]:
        done = subprocess.run([*CKESC, "run", "--rig", "rig.toml", "--reports", str(tmp_path / reports), "4.4.27",
                               "--", "-k", POWER_CYCLE_TEST], cwd=tmp_path, env=env, capture_output=True, text=True,
                              timeout=300)
        [run] = [p for p in (tmp_path / reports).iterdir() if p.is_dir() and not p.is_symlink()]
        assert (run / "batch.json").is_file(), done.stdout[-3000:] + done.stderr[-3000:]
        return done, {b["name"]: b for b in json.loads((run / "batch.json").read_text())["benches"]}

    done, benches = batch("reports")
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert {n: b["status"] for n, b in benches.items()} == {"shared": "PASS", "sim": "PASS"}, benches
    assert switch.switched[:2] == ["off", "on"], switch.switched  # through labgrid's NetworkPowerDriver
    assert lab.holder("rig1") is None  # released by the bench's worker
    taken = lab.client("-p", "rig1", "acquire", user="alice")
    assert taken.returncode == 0, taken.stderr
    done, benches = batch("reports2")
    assert done.returncode == 3, done.stdout[-3000:] + done.stderr[-3000:]
    assert benches["sim"]["status"] == "PASS" and benches["shared"]["status"] == "ABSENT", benches
    assert "locked by" in benches["shared"]["why"] and "alice" in benches["shared"]["why"], benches["shared"]
    assert lab.holder("rig1").endswith("/alice")
