"""The suite and the explorer against an ESC we did not write (issue #22's plugtest): ``tools/clean-room-esc``, an
independent CKESC 2.1 ESC written from the document alone (its README says how, and every choice it makes where
the document is free), on a bare socketcand hub (``ckesc emulate --nodes none``), its power switched by signals
through ``--power command``: a third-party DUT as a bench meets one, every part a real process.

In every CI run: a handful of sections in real time pass it (no FAIL, no ERROR), the suite catches one of its
interaction defects (about 40 s together), and the explorer's shrunk programs of four others show them and
nothing on the correct ESC (about 40 s). ``slow``: the whole suite passes it, ``ckesc explore`` finds nothing on
it, and explores each of its defects.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from procs import CKESC, Emulator, end
from procs import env as _env

pytestmark = pytest.mark.realtime  # wall-clock timing with real processes: one at a time under xdist (tests/conftest.py)

ROOT = Path(__file__).resolve().parents[2]
ESC = ROOT / "tools" / "clean-room-esc" / "clean_room_esc.py"
PROFILE = ROOT / "tools" / "clean-room-esc" / "clean-room.toml"
#: quick sections in real time (about 20 s of protocol time): answer slots, suspend / resume and MSG_EXP timers,
#: LED and rotation saves across power cycles, 242 (the whole suite is the slow test below)
SECTIONS = ("4.4.2", "4.4.3", "4.4.20", "4.4.21", "4.4.28")


class CleanRoom:
    """The hub and the clean-room ESC on it, each its own process; ``bench`` is the bench options of ``ckesc run``
    and ``ckesc explore`` that reach it (socketcand, power by signals, the bit rate through a file)."""

    def __init__(self, tmp: Path, *defects: str, hub: tuple[str, ...] = ()) -> None:
        # hub: the hub's own options (--no-echo-own, --handles ...); the ESC opens a name of its own ("esc"): another
        # node on the bus, not a handle of the host's adapter (which --handles separate|one would keep apart)
        self.hub = Emulator(tmp, "--nodes", "none", *hub)
        rate = tmp / "bitrate"
        rate.write_text("500000\n")
        args = [sys.executable, str(ESC), "--interface", "socketcand", "--channel", "esc", "--bus-arg", "host=127.0.0.1",
                "--bus-arg", f"port={self.hub.port}", "--node", "1", "--flash", str(tmp / "flash.json"),
                "--bus-bitrate-file", str(rate)]
        for d in defects:
            args += ["--defect", d]
        self.esc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env(tmp))
        assert self.esc.stdout is not None
        line = self.esc.stdout.readline()
        m = re.match(r"ready pid=(\d+)", line)
        assert m, line + (self.esc.stderr.read() if self.esc.stderr else "")
        pid = m.group(1)
        self.bench = ["--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0",
                      "--can-config", "host=127.0.0.1", "--can-config", f"port={self.hub.port}",
                      "--can-config", "tcp_tune=True", "--profile", str(PROFILE), "--power", "command",
                      "--power-off-cmd", f"kill -USR1 {pid}", "--power-on-cmd", f"kill -USR2 {pid}",
                      "--can-bitrate-cmd", f"sh -c 'echo {{bitrate}} > {rate}'"]

    def close(self) -> None:
        end(self.esc)  # SIGTERM: the ESC writes its flash file and exits
        self.hub.close()

    def __enter__(self) -> CleanRoom:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _run(tmp: Path, cr: CleanRoom, *args: str, timeout: float = 900) -> tuple[subprocess.CompletedProcess, dict]:
    reports = tmp / "reports"
    done = subprocess.run([*CKESC, "run", "-q", *cr.bench, "--reports", str(reports), *args], capture_output=True,
                          text=True, timeout=timeout, env=_env(tmp), cwd=tmp)
    (results,) = reports.glob("2*/results.json")
    return done, json.loads(results.read_text())


def _verdicts(results: dict, *outcomes: str) -> list[str]:
    return [f"{r['nodeid']} {r['outcome']}: {(r.get('message') or '')[:300]}" for r in results["results"]
            if r["outcome"] in outcomes]


def test_the_suite_passes_an_esc_of_another_make(tmp_path):
    """Sections whose readings differ most between makes (answer slots, suspend/resume and MSG_EXP timers, LED,
    rotation and source saves, counters): no FAIL and no ERROR on an ESC written without our model's choices."""
    with CleanRoom(tmp_path) as cr:
        done, results = _run(tmp_path, cr, *SECTIONS)
    bad = _verdicts(results, "FAIL", "ERROR")
    assert not bad, "\n".join(bad)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert {r["section"] for r in results["results"] if r["outcome"] == "PASS"} >= set(SECTIONS)


#: the robustness section in the same run (its whole real-time runs: test_robustness_realtime.py, slow): a frame type
#: the ESC takes one byte long (its R17 defect, README), and one it checks exactly
ROBUSTNESS_SUBSET = "test_malformed_frames_are_ignored and (set_rotation or get_esc_id)"


def test_the_suite_catches_a_defect_of_the_esc_of_another_make(tmp_path):
    """Its ``answer_slot_from_boot_node``: after a Set ID, MSG Control and GET_ESC_ID are answered in the slot of
    the node id the ESC booted with (R2 wants the current one's). In the same run, in real time, the robustness
    section FAILs its one-byte-long Set Rotation taken on R17, naming the frame, and passes its GET_ESC_ID."""
    with CleanRoom(tmp_path, "answer_slot_from_boot_node") as cr:
        done, results = _run(tmp_path, cr, "4.4.3", "robustness", "--", "-k", f"test_s4_4_3 or ({ROBUSTNESS_SUBSET})")
    failed = [r for r in results["results"] if r["outcome"] == "FAIL" and r["section"] == "4.4.3"]
    assert any("R2" in r["requirements"] + r.get("bus_rules", []) for r in failed), "\n".join(_verdicts(results, "FAIL", "PASS"))
    r17 = {r["nodeid"].split("::")[-1]: r for r in results["results"] if r["section"] == "robustness"}
    assert sorted(r17) == ["test_malformed_frames_are_ignored[get_esc_id]", "test_malformed_frames_are_ignored[set_rotation]"]
    message = r17["test_malformed_frames_are_ignored[set_rotation]"]["message"]
    assert message.startswith("[R17") and "taken, one at a time: one byte long" in message, message[:600]
    # GET_ESC_ID is checked exactly (its payload ==): the section's own verdict passes it. A FAIL of the bus rules'
    # report timing (R9) alone is the loaded machine's, as this run's other sections tolerate it
    esc_id = r17["test_malformed_frames_are_ignored[get_esc_id]"]
    assert esc_id["outcome"] == "PASS" or (esc_id["outcome"] == "FAIL" and esc_id["message"].startswith("[bus rules R9")
                                           and "R17" not in esc_id["message"]), esc_id["message"][:600]
    assert done.returncode == 1


@pytest.mark.slow
def test_the_whole_suite_passes_an_esc_of_another_make(tmp_path):
    """Every section passes it but robustness, which FAILs it on R17 only: its length checks take a frame one byte
    longer than its table (and 240/242 an empty request), a defect of that ESC (tools/clean-room-esc/README.md)."""
    with CleanRoom(tmp_path) as cr:
        done, results = _run(tmp_path, cr, "--allow-motor-spin", timeout=1800)
    bad = _verdicts(results, "FAIL", "ERROR")
    r17 = [r for r in results["results"] if r["section"] == "robustness" and r["outcome"] == "FAIL"]
    assert r17 and all("R17" in r["message"] for r in r17), "\n".join(bad)
    rest = [v for v in bad if "test_robustness_" not in v]
    assert not rest, "\n".join(rest)


@pytest.mark.slow
def test_explore_finds_nothing_on_an_esc_of_another_make(tmp_path):
    with CleanRoom(tmp_path) as cr:
        done = subprocess.run([*CKESC, "explore", *cr.bench, "--budget", "5m", "--seed", "1", "--database", "none",
                               "--reports", str(tmp_path / "reports"), "-q"], capture_output=True, text=True,
                              timeout=1200, env=_env(tmp_path), cwd=tmp_path)
    assert done.returncode == 0, done.stdout[-5000:]


def _session(cr: CleanRoom):
    """An exploration session on the clean-room bench, from the bench options as ``ckesc explore`` parses them."""
    from ckesc.cli import build_parser
    from ckesc.explore.command import bench_options, open_session

    return open_session(bench_options(build_parser().parse_args(["explore", *cr.bench])))


def _shrunk():
    """What ``ckesc explore`` shrank each of these defects to in real time (seed 1), and the problem it showed."""
    from ckesc.explore.actions import Action

    def send(name, **fields):
        return Action("send", name, fields)
    return {
        "rotation_query_saves_suspend": ([send("msg_control", option=0, command=0x55555555),
                                          send("set_rotation", rotation=0xFF), Action("power")], "stream|msg1 stopped, normal"),
        "answer_slot_from_boot_node": ([send("set_id", node_id=17, throttle_channel=1)],
                                       "answer|get_esc_id answer before its slot"),
        "powerup_counted_twice_after_baud": ([send("set_baud", baud=0), Action("power"), send("maintenance_information", option=2)],
                                             "answer|maintenance_information.power_ups"),
        "throttle_select_breaks_10b": ([send("throttle_select", source=0), Action("stream", "raw_command_10b"),
                                        Action("wait", seconds=0.3)], "status|status 0x2000"),
    }


def test_explore_s_shrunk_programs_show_the_defects_and_nothing_on_the_correct_esc(tmp_path):
    """The four defects the explorer reached only with this issue's second pass (a mode's requests then a power-up,
    the answer slot after Set ID, Set Baud on a real bus, a write then every throttle format): their shrunk
    programs show them in real time, and show nothing on the correct ESC (about 40 s)."""
    shrunk = _shrunk()
    for defects, tmp in ((tuple(shrunk), tmp_path / "defects"), ((), tmp_path / "correct")):
        tmp.mkdir()
        with CleanRoom(tmp, *defects) as cr:
            session = _session(cr)
            try:
                for name, (program, key) in shrunk.items():
                    findings = session.run(program).findings
                    if defects:
                        assert key in {f.key for f in findings}, f"{name}: " + "\n".join(f.text() for f in findings)
                        continue
                    if findings and all(f.kind == "interval" or (f.kind == "bus_rule" and f.requirements[:1] == ["R9"])
                                        for f in findings):
                        # report timing alone: the ESC is a Python process on the host's loaded cores, and a stall
                        # moves a mean of a few gaps beyond its two ends' jitter (R9). A false finding of the judge
                        # comes back on the same program; the machine's stall does not
                        warnings.warn(f"{name} on the correct ESC at load average {os.getloadavg()[0]:.1f}: "
                                      + "; ".join(f.text().splitlines()[0] for f in findings) + ": run again",
                                      stacklevel=1)
                        findings = session.run(program).findings
                    assert not findings, f"{name} on the correct ESC: " + "\n".join(f.text() for f in findings)
            finally:
                session.close()
            assert session.left is None


#: the clean-room ESC's interaction defects (``--list-defects``; its README says what each breaks)
DEFECTS = ("freq_save_clobbers_rotation", "resume_reloads_default_intervals", "led_ram_saved_by_other_writes",
           "powerup_counted_twice_after_baud", "commloss_sticks_after_can_test", "exp_exit_drops_msg3",
           "flash_save_closes_window", "throttle_select_breaks_10b", "rotation_query_saves_suspend",
           "answer_slot_from_boot_node")


def test_the_defects_named_here_are_the_esc_s_own():
    done = subprocess.run([sys.executable, str(ESC), "--list-defects"], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert {line.split(":")[0] for line in done.stdout.splitlines() if line.strip()} == set(DEFECTS), done.stdout


@pytest.mark.slow
@pytest.mark.parametrize("defect", DEFECTS)
def test_explore_finds_a_defect_of_an_esc_of_another_make(tmp_path, defect):
    """Issue #22's measure: each defect found within 10 minutes in real time (a matrix of up to 100 minutes)."""
    with CleanRoom(tmp_path, defect) as cr:
        done = subprocess.run([*CKESC, "explore", *cr.bench, "--budget", "10m", "--seed", "1", "--first",
                               "--database", "none", "--reports", str(tmp_path / "reports"), "-q"],
                              capture_output=True, text=True, timeout=1800, env=_env(tmp_path), cwd=tmp_path)
    assert done.returncode == 1, done.stdout[-5000:]
