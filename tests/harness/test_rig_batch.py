"""``ckesc run --rig`` for real (issue #13): pytest-xdist workers, simulated benches and ``ckesc emulate``
processes behind their own socketcand and control ports, a bench whose DUT is not there, a failing bench and
Ctrl-C mid-batch; each bench's report whole in ``reports/<ts>/<bench>/`` and the batch's own beside them,
read back with junitparser and python-can. A few quick sections keep it short."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest
from junitparser import JUnitXml
from procs import CKESC, Emulator
from procs import env as _env

from ckesc.protocol.frame import decode

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

pytest.importorskip("xdist", reason="the batch runs through pytest-xdist: pip install -e '.[rig]'")

SECTIONS = ("4.4.3", "4.4.28")


def _power(emu: Emulator) -> str:
    cmd = f"{sys.executable} -m ckesc control --port {emu.control} power"
    return f"power = {{ command = {{ off = {json.dumps(cmd + ' off')}, on = {json.dumps(cmd + ' on')} }} }}"


#: the emulator on a real-time bench: a stated timing error as on a real one (the process is scheduled late at times)
PROFILE = """[dut]
name = "ckesc emulate behind socketcand"
[capabilities]
led = true
motor = true
multi_node = false
[timing]
error_s = 0.005
boot_s = 0.5
"""


def _socketcand_bench(name: str, emu: Emulator) -> str:
    return (f"[bench.{name}]\nbus = {{ interface = \"socketcand\", host = \"127.0.0.1\", port = {emu.port}, channel = \"can0\" }}\n"
            f"profile = \"realtime.toml\"\n{_power(emu)}\n")


def _write_rig(tmp: Path, rig: str) -> None:
    (tmp / "rig.toml").write_text(rig)
    (tmp / "realtime.toml").write_text(PROFILE)  # beside the rig file: its paths are taken from there


def _batch(tmp: Path, rig: str, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    _write_rig(tmp, rig)
    return subprocess.run([*CKESC, "run", "--rig", "rig.toml", "--reports", str(tmp / "reports"), *args], cwd=tmp,
                          env=_env(tmp), capture_output=True, text=True, timeout=timeout)


def _batch_dir(tmp: Path) -> Path:
    dirs = [p for p in (tmp / "reports").iterdir() if p.is_dir() and not p.is_symlink()]
    assert len(dirs) == 1, dirs
    assert (tmp / "reports" / "latest").resolve() == dirs[0].resolve()
    return dirs[0]


def _litter(tmp: Path) -> list[str]:
    return sorted(p.name for p in (tmp / "tmp").iterdir())


def _closed_port() -> int:
    """A port on 127.0.0.1 nothing listens on (a socketcand host that is down)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_batch_of_emulated_benches_reports_each_whole_and_one_absent_dut_never_stops_the_others(tmp_path):
    """Two simulated benches and a real-time ``ckesc emulate`` over socketcand pass with their own reports; a
    bench whose ESC has no power (it answers nothing), a bus with no ESC on it and a socketcand host that is
    down are ABSENT; exit 3."""
    with Emulator(tmp_path) as live, Emulator(tmp_path, "--unpowered") as dark:
        rig = ("[bench.sim-a]\n\n[bench.sim-b]\nemulator = { nodes = [1], seed = 3, options = { report_timer = \"grid\" } }\n\n"
               + _socketcand_bench("live", live) + "\n" + _socketcand_bench("dark", dark)
               + "\n[bench.empty]\nbus = { interface = \"virtual\", channel = \"nobody-here\" }\n"
               + f"\n[bench.down]\nbus = {{ interface = \"socketcand\", host = \"127.0.0.1\", port = {_closed_port()}, "
                 "channel = \"can0\" }\n")
        done = _batch(tmp_path, rig, *SECTIONS)
    out = done.stdout
    assert done.returncode == 3, out[-3000:] + done.stderr[-3000:]
    said = [line for line in out.splitlines() if not line.startswith("time: ")]
    assert len(said) == 8 and not done.stderr, out + done.stderr  # no retry warnings of python-can
    # each bench that runs says its time left as it enters a section (issue #21)
    timed = {line.split(":")[1].strip() for line in out.splitlines() if line.startswith("time: ")}
    assert timed == {"sim-a", "sim-b", "live"}, out
    assert any(line.startswith("time: live: [4.4.28 ") and " left" in line for line in out.splitlines()), out
    batch = _batch_dir(tmp_path)
    # one line per bench finished, each with its status
    lines = [line for line in out.splitlines() if line.startswith("bench ")]
    assert sorted(line.split(":")[0] for line in lines) == ["bench dark", "bench down", "bench empty", "bench live",
                                                            "bench sim-a", "bench sim-b"], out
    assert any(line.startswith("bench dark: ABSENT") and "no ESC answered GET_ESC_ID" in line for line in lines), out
    assert any(line.startswith("bench down: ABSENT") and "cannot open the CAN bus" in line for line in lines), out
    doc = json.loads((batch / "batch.json").read_text())
    status = {b["name"]: b["status"] for b in doc["benches"]}
    assert status == {"sim-a": "PASS", "sim-b": "PASS", "live": "PASS", "dark": "ABSENT", "empty": "ABSENT",
                      "down": "ABSENT"}, doc
    assert "cannot open the CAN bus" in (batch / "down" / "setup-error.txt").read_text()
    assert doc["exit_status"] == 3 and doc["sections"] == list(SECTIONS)
    by_name = {b["name"]: b for b in doc["benches"]}
    assert by_name["live"]["identity"]["lane"] == "bus" and by_name["live"]["identity"]["power"] == "command"
    assert by_name["sim-a"]["sections"] == {"4.4.3": "PASS", "4.4.28": "PASS"}
    # each bench's report, exactly as one bench's run writes it, in reports/<ts>/<bench>/
    for name in ("sim-a", "sim-b", "live"):
        run = json.loads((batch / name / "results.json").read_text())
        assert run["info"]["run_id"] == f"{batch.name}/{name}"
        assert {r["section"] for r in run["results"]} == set(SECTIONS)
        assert all(r["outcome"] in ("PASS", "OBSERVED", "INCONCLUSIVE", "SKIPPED") for r in run["results"]), run["results"]
        assert (batch / name / "report.html").is_file() and (batch / name / "summary.txt").is_file()
        assert list((batch / name / "traces").glob("*.blf"))
    assert json.loads((batch / "sim-b" / "results.json").read_text())["info"]["faults"] == ""
    # no ESC answers on its bus: its bench proof says so before any test (issue #29), as a one-bench run's exit 2
    assert "no ESC answered GET_ESC_ID" in (batch / "dark" / "setup-error.txt").read_text()
    # the merged JUnit: one testsuite per bench and section, each case in its bench's package
    xml = JUnitXml.fromfile(str(batch / "junit.xml"))
    suites = {s.name: s for s in xml}
    for name in ("sim-a", "sim-b", "live"):
        assert {n.split(": ")[1].split(" ")[0] for n in suites if n.startswith(f"{name}: ")} == set(SECTIONS)
        assert all(case.classname.startswith(f"ckesc.{name}.s4_4_") for n, s in suites.items() if n.startswith(name + ":")
                   for case in s)
    # batch.html: the bench x section matrix, the identities and links to each report
    page = (batch / "batch.html").read_text()
    for name in ("sim-a", "sim-b", "live", "dark", "down"):
        assert f'data-bench="{name}"' in page
    assert 'href="sim-a/report.html"' in page and 'data-section="4.4.28"' in page and "id=identity" in page
    assert "id=matrix" in page  # the requirement x bench matrix of ckesc compare
    assert _litter(tmp_path) == []


def test_the_example_rig_runs_here(tmp_path):
    example = Path(__file__).resolve().parents[2] / "fixtures" / "rigs" / "example.toml"
    done = subprocess.run([*CKESC, "run", "--rig", str(example), "--reports", str(tmp_path / "reports"), "4.4.28"],
                          cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    doc = json.loads((_batch_dir(tmp_path) / "batch.json").read_text())
    assert [(b["name"], b["status"]) for b in doc["benches"]] == [("sim-a", "PASS"), ("sim-b", "PASS"), ("realtime-c", "PASS")]


def test_a_failing_bench_fails_the_batch_and_the_others_still_pass(tmp_path):
    done = _batch(tmp_path, "[bench.good]\n\n[bench.bad]\nemulator = { faults = [\"get_esc_id_wrong_node\"] }\n", "4.4.3")
    assert done.returncode == 1, done.stdout[-3000:] + done.stderr[-3000:]
    batch = _batch_dir(tmp_path)
    doc = json.loads((batch / "batch.json").read_text())
    assert {b["name"]: b["status"] for b in doc["benches"]} == {"good": "PASS", "bad": "FAIL"}
    xml = JUnitXml.fromfile(str(batch / "junit.xml"))
    failures = {s.name.split(":")[0]: s.failures for s in xml}
    assert failures["good"] == 0 and failures["bad"] > 0
    assert '<span class="v v-FAIL">FAIL</span>' in (batch / "batch.html").read_text()


def _host_throttles(trace: Path) -> list[list[int]]:
    """The channels of every RawCommand the host sent in a trace, in order."""
    out = []
    with can.BLFReader(str(trace)) as reader:
        for msg in reader:
            try:
                f = decode(msg)
            except Exception:  # noqa: BLE001 - frames of no known layout are not throttle commands
                continue
            if f.name.startswith("raw_command") and f.source == 0:
                out.append(list(f.fields["channels"]))
    return out


def _wait_for(what: str, check, timeout: float = 240.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        found = check()
        if found:
            return found
        time.sleep(0.2)
    pytest.fail(f"never happened: {what}")


def _children(pid: int) -> list[int]:
    try:
        return [int(c) for c in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


@contextlib.contextmanager
def _running_batch(tmp: Path, *args: str):
    """``ckesc run --rig rig.toml`` in its own session (as a terminal's foreground job), killed if the test fails."""
    proc = subprocess.Popen([*CKESC, "run", "--rig", "rig.toml", "--reports", str(tmp / "reports"), *args], cwd=tmp,
                            env=_env(tmp), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True)
    try:
        yield proc
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_ctrl_c_stops_every_bench_with_zero_throttle_and_still_writes_the_batch_report(tmp_path):
    with Emulator(tmp_path) as live:
        _write_rig(tmp_path, "[bench.sim-a]\n\n[bench.sim-b]\n\n" + _socketcand_bench("live", live))
        with _running_batch(tmp_path) as proc:
            benches = tmp_path / "reports"
            _wait_for("every bench is 3 tests into the suite", lambda: len(found := [
                len(list(d.glob("traces/*"))) for d in benches.glob("2*/*") if d.is_dir()]) == 3 and min(found) >= 3)
            os.killpg(proc.pid, signal.SIGINT)  # Ctrl-C at a terminal: the foreground process group
            out, _ = proc.communicate(timeout=180)
    assert proc.returncode == 130, out[-3000:]
    assert "SIGINT: stopping every bench" in out and "Traceback" not in out, out[-3000:]
    batch = _batch_dir(tmp_path)
    doc = json.loads((batch / "batch.json").read_text())
    assert doc["interrupted"] is True and doc["exit_status"] == 130
    assert {b["name"]: b["status"] for b in doc["benches"]} == {"sim-a": "INTERRUPTED", "sim-b": "INTERRUPTED",
                                                                 "live": "INTERRUPTED"}, doc["benches"]
    for name in ("sim-a", "sim-b", "live"):
        run = json.loads((batch / name / "results.json").read_text())
        assert run["info"]["incomplete"].startswith("interrupted"), run["info"]
        assert run["not_run"] and not [r for r in run["results"] if r["outcome"] == "ERROR"]
        # the DUT's own lane (not a multi-ESC test's private bench, <test>.bench.blf): the last throttle it was sent
        last = max((p for p in (batch / name / "traces").glob("*.blf") if not p.name.endswith(".bench.blf")),
                   key=lambda p: p.stat().st_mtime)
        throttles = _host_throttles(last)
        assert throttles and not any(throttles[-1]), (name, last.name, throttles[-3:])  # zero throttle, last
    assert (batch / "batch.html").is_file() and (batch / "junit.xml").is_file()
    assert _litter(tmp_path) == []


def test_a_bench_whose_dut_goes_dark_or_whose_worker_dies_is_reported_and_the_others_finish(tmp_path):
    """Mid-batch, one bench's ESC loses its power (ABORTED: what ran has verdicts) and another bench's worker
    process is killed (BROKEN: no report); the simulated bench runs its whole selection and passes; exit 3."""
    with Emulator(tmp_path) as live:
        _write_rig(tmp_path, "[bench.sim]\n\n[bench.rt]\nlane = \"realtime\"\n\n" + _socketcand_bench("live", live))
        with _running_batch(tmp_path, "4.4.22", "4.4.4", "4.4.27") as proc:
            reports = tmp_path / "reports"
            _wait_for("a test of the live bench ran", lambda: list(reports.glob("2*/live/traces/*")))
            subprocess.run([*CKESC, "control", "--port", str(live.control), "power", "off"], check=True, capture_output=True,
                           timeout=30, env=_env(tmp_path))
            # the worker of bench rt is the one whose child is its own `ckesc emulate` (the real-time lane)
            _wait_for("a test of the rt bench ran", lambda: list(reports.glob("2*/rt/traces/*")))
            os.kill(next(w for w in _children(proc.pid) if _children(w)), signal.SIGKILL)
            out, _ = proc.communicate(timeout=300)
    assert proc.returncode == 3, out[-3000:]
    batch = _batch_dir(tmp_path)
    doc = json.loads((batch / "batch.json").read_text())
    by_name = {b["name"]: b for b in doc["benches"]}
    assert by_name["sim"]["status"] == "PASS", by_name["sim"]
    assert by_name["live"]["status"] == "ABORTED" and "stopped answering" in by_name["live"]["why"], by_name["live"]
    assert by_name["rt"]["status"] == "BROKEN" and "worker process ended" in by_name["rt"]["why"], by_name["rt"]
    sim = json.loads((batch / "sim" / "results.json").read_text())
    assert not sim["not_run"] and {r["section"] for r in sim["results"]} == {"4.4.22", "4.4.4", "4.4.27"}
    assert any(line.startswith("bench rt: BROKEN") for line in out.splitlines()), out
    assert (batch / "batch.html").is_file()


#: sections with a Set ID / Set Baud window to overlap (4.4.18, 4.4.19) and persistence tests whose cold boots a
#: group shares (4.4.21, 4.4.22)
PLANNED = ("4.4.18", "4.4.19", "4.4.21", "4.4.22")


@pytest.mark.slow  # two batches of four sections each; CI keeps the batch's reports, failures and Ctrl-C (above)
def test_a_bench_in_a_batch_runs_its_plan_as_it_does_alone(tmp_path):
    """Issue #21: each bench of a batch runs in the same order, with the same shared windows and cold boots, as the
    bench alone (the run-order plan in every xdist worker), so its protocol time is the same to the millisecond."""
    alone = subprocess.run([*CKESC, "run", "-q", "--reports", str(tmp_path / "alone"), "--emulator-seed", "7", *PLANNED],
                           cwd=tmp_path, env=_env(tmp_path), capture_output=True, text=True, timeout=300)
    assert alone.returncode == 0, alone.stdout[-3000:] + alone.stderr[-3000:]
    done = _batch(tmp_path, "[bench.one]\nemulator = { seed = 7 }\n\n[bench.two]\nemulator = { seed = 7 }\n", *PLANNED)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    solo = json.loads((tmp_path / "alone" / "latest" / "results.json").read_text())
    assert solo["info"]["order"] == "overlap" and solo["info"]["epochs"] and solo["info"]["cold_boots"]
    for name in ("one", "two"):
        run = json.loads((_batch_dir(tmp_path) / name / "results.json").read_text())
        assert run["info"]["order"] == "overlap"
        assert [r["nodeid"] for r in run["results"]] == [r["nodeid"] for r in solo["results"]]  # the same order
        assert [(r["nodeid"], r["outcome"]) for r in run["results"]] == [(r["nodeid"], r["outcome"]) for r in solo["results"]]
        assert run["info"]["lane_seconds"] == solo["info"]["lane_seconds"]
        for key in ("epochs", "cold_boots"):
            assert [{k: e.get(k) for k in ("name", "for", "at")} for e in run["info"][key]] == \
                   [{k: e.get(k) for k in ("name", "for", "at")} for e in solo["info"][key]], key
