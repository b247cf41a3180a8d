"""One front door for every command (issue #38): each mistake a user can make, tried as a new user would, as a real
``ckesc`` process: exit 2, one line on stderr that names the option, no traceback, within seconds, and nothing done
first (no file or directory written, no budget or duration spent). The mistakes are the issue's, and for every
command the same kinds: an output it cannot write, a number below zero or zero where zero makes no sense, a duration
without a known unit."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

#: (command line, words the one line must hold); ``{blocked}``: a path under a file (nobody can make it, root
#: included), ``{tmp}``: the test's directory. Each is run in an empty working directory.
MISTAKES = [
    # the issue's own
    (["explore", "--budget", "5s", "--reports", "{blocked}/reports"], ["reports directory", "--reports"]),
    (["profile", "init", "--output", "{blocked}/p.toml"], ["profile file", "--output"]),
    (["profile", "init", "--output", "{tmp}/no-such-dir/p.toml"], ["no directory", "--output"]),
    (["soak", "--reports", "{blocked}/reports"], ["reports directory", "--reports"]),
    # a directory whose permissions say yes to root and whose file system says no (/proc): the kernel decides
    (["explore", "--budget", "5s", "--reports", "/proc/ckesc-reports"], ["reports directory", "--reports"]),
    (["soak", "--reports", "/proc/ckesc-reports"], ["reports directory", "--reports"]),
    (["soak", "--duration", "0"], ["--duration", "0 is zero"]),
    (["soak", "--duration", "-5m"], ["--duration", "below zero"]),
    (["soak", "--duration", "90x"], ["--duration", "'90x' is not a duration"]),
    (["run", "--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0"], ["--can-config host=", "port="]),
    (["run", "--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0", "--can-config", "host=127.0.0.1",
      "--can-config", "port={closed_port}"], ["connection refused"]),
    # the same kinds of mistake, every command
    (["run", "--reports", "{blocked}/reports"], ["reports directory", "--reports"]),
    (["explore", "--budget", "0"], ["--budget", "zero"]),
    (["explore", "--budget", "-1h"], ["--budget", "below zero"]),
    (["explore", "--max-programs", "0"], ["--max-programs", "zero"]),
    (["explore", "--max-steps", "-2"], ["--max-steps", "below zero"]),
    (["explore", "--database", "{blocked}/db"], ["database directory", "--database"]),
    (["soak", "--rate", "-400"], ["--rate", "below zero"]),
    (["soak", "--throttle-profile", "-1m:0"], ["--throttle-profile", "below zero"]),
    (["selftest", "--jobs", "0"], ["--jobs", "zero"]),
    (["selftest", "--faults", "answer_lat"], ["--faults", "unknown fault", "did you mean"]),
    (["selftest", "--faults", "none", "--out", "{blocked}/table.md"], ["output file", "--out"]),
    (["compare", "{tmp}/a", "{tmp}/b", "--json", "{blocked}/c.json"], ["output file", "--json"]),
    (["compare", "{tmp}/a", "{tmp}/b", "--html", "{tmp}"], ["is a directory", "--html"]),
    (["check-log", "{log}", "--json", "{blocked}/s.json"], ["output file", "--json"]),
    (["check-log", "{tmp}/no-such.log"], ["capture", "is not readable (no such file)"]),
    (["check-log", "{log}", "--tolerance", "-1"], ["--tolerance", "below zero"]),
    (["emulate", "--socketcand", "0", "--duration", "0"], ["--duration", "zero"]),
    (["emulate", "--socketcand", "0", "--boot-time", "-1"], ["--boot-time", "below zero"]),
    (["emulate", "--socketcand", "0", "--flash-path", "{blocked}/flash.json"], ["flash file", "--flash-path"]),
    (["control", "--port", "1", "--timeout", "0", "status"], ["--timeout", "zero"]),
    (["control", "--port", "1", "power", "cycle", "--off-time", "-1"], ["--off-time", "below zero"]),
    (["report", "{blocked}"], ["no results.json"]),
    (["emulate", "--socketcand", "70000"], ["--socketcand", "not a port"]),
    (["control", "--port", "70000", "status"], ["--port", "not a port"]),
    (["run", "--time-from", "{tmp}/no-such-results.json"], ["results.json", "(no such file)", "--time-from"]),
    (["run", "--bus-open-timeout", "-1"], ["--bus-open-timeout", "below zero"]),
    (["run", "--baseline", "{tmp}/no-such-run"], ["--baseline", "no such run directory"]),
    (["run", "--baseline", "{tmp}/a"], ["--baseline", "no results.json"]),
    (["run", "--baseline", "{log}"], ["--baseline", "not JSON"]),
    (["run", "--baseline-threshold", "-5"], ["--baseline-threshold", "not between 0 and 100"]),
    (["run", "--rig", "{tmp}/rig.toml", "--baseline", "{tmp}/a"], ["--baseline gates one bench's run"]),
    (["soak", "--power-cmd-timeout", "0"], ["--power-cmd-timeout", "zero"]),
    (["explore", "--replay", "{tmp}/no-such.replay.json"], ["replay file", "is not readable (no such file): give another with --replay"]),
    (["bisect", "--images", "{tmp}/no-such.txt", "4.4.27"], ["image list", "is not readable (no such file): give another with --images"]),
    (["bisect", "--images", "{log}", "4.4.27"], ["--images", "1 image(s): a bisect needs the known-good image first"]),
    (["bisect", "--images", "{tmp}/a", "4.4.27"], ["--images", "holds no image"]),
    (["bisect", "--images", "{tmp}", "--reports", "{blocked}/reports", "4.4.27"], ["reports directory", "--reports"]),
    (["bisect", "--images", "{tmp}", "--tries", "0", "4.4.27"], ["--tries"]),
    # the same words for the same mistake, whichever command meets it
    (["run", "--emulator-faults", "answer_lat"], ["--emulator-faults: unknown fault 'answer_lat'", "did you mean"]),
    (["emulate", "--socketcand", "0", "--faults", "answer_lat@1"], ["--faults: unknown fault 'answer_lat'", "did you mean"]),
    (["explore", "--selftest", "answer_lat"], ["--selftest: unknown fault 'answer_lat'", "did you mean"]),
]


def _closed_port() -> int:
    """A port nobody listens on: bound, then let go."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _tree(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


@pytest.mark.parametrize("argv, words", MISTAKES, ids=[" ".join(a).replace("{", "").replace("}", "") for a, _ in MISTAKES])
def test_a_mistake_is_one_line_exit_2_before_any_work(tmp_path, argv, words):
    (tmp_path / "blocked").write_text("a file where a directory should be\n")
    (tmp_path / "capture.log").write_text("(1700000000.000000) can0 00000000#00\n")
    for run in ("a", "b"):
        (tmp_path / run).mkdir()
    work = tmp_path / "work"
    work.mkdir()
    values = {"blocked": str(tmp_path / "blocked"), "tmp": str(tmp_path), "log": str(tmp_path / "capture.log"),
              "closed_port": str(_closed_port())}
    args = [a.format(**values) for a in argv]
    before = _tree(tmp_path)
    env = {k: v for k, v in os.environ.items() if not k.startswith("CAN_")} | {"TMPDIR": str(work)}
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "ckesc", *args], cwd=work, env=env, capture_output=True, text=True,
                          timeout=60)
    took = time.monotonic() - started
    said = done.stdout + done.stderr
    assert "Traceback" not in said, said
    assert done.returncode == 2, said
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, done.stderr
    for w in words:
        assert w in lines[0], lines[0]
    assert _tree(tmp_path) == before, "the command wrote something before refusing"
    assert took < 15, f"{took:.1f} s: a mistake is refused before any work"  # (the budget above is 5 s: not spent)


def test_a_refused_connection_is_said_at_once_and_suggests_no_longer_limit(tmp_path):
    """Nobody listening at the socketcand address: not the 5 s bus-open limit, and no advice to lengthen it."""
    started = time.monotonic()
    done = subprocess.run([sys.executable, "-m", "ckesc", "run", "--dut", "bus", "--can-interface", "socketcand",
                           "--can-channel", "can0", "--can-config", "host=127.0.0.1", "--can-config",
                           f"port={_closed_port()}", "--bus-open-timeout", "30"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=60)
    took = time.monotonic() - started
    assert done.returncode == 2 and "connection refused" in done.stderr, done.stdout + done.stderr
    assert "--bus-open-timeout" not in done.stderr
    assert took < 15, f"{took:.1f} s with a 30 s open limit: the refusal waited for it"


def test_a_missing_reports_directory_that_could_be_made_is_fine_and_made_by_nothing_but_the_run(tmp_path):
    """The check makes nothing: a mistake found after it (here the bus, opened after the reports directory was
    checked) leaves no directory behind (the check made it, and the refused run left it, before issue #38)."""
    done = subprocess.run([sys.executable, "-m", "ckesc", "run", "--reports", str(tmp_path / "new" / "reports"),
                           "--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0", "--can-config",
                           "host=127.0.0.1", "--can-config", f"port={_closed_port()}"], cwd=tmp_path, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == 2 and "connection refused" in done.stderr, done.stdout + done.stderr
    assert not (tmp_path / "new").exists()


def test_a_daemon_that_takes_the_connection_and_never_answers_is_given_the_open_limit(tmp_path):
    """The other side of the refusal: something listens but never says socketcand's hello, so the bus-open limit is
    what ends the wait, and only then is a longer one suggested."""
    import socket

    with socket.socket() as silent:
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        port = silent.getsockname()[1]
        started = time.monotonic()
        done = subprocess.run([sys.executable, "-m", "ckesc", "run", "--dut", "bus", "--can-interface", "socketcand",
                               "--can-channel", "can0", "--can-config", "host=127.0.0.1", "--can-config", f"port={port}",
                               "--bus-open-timeout", "1"], cwd=tmp_path, capture_output=True, text=True, timeout=60)
        took = time.monotonic() - started
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert done.returncode == 2 and len(lines) == 1, done.stdout + done.stderr
    assert "no answer within 1 s" in lines[0] and "--bus-open-timeout gives it longer" in lines[0], lines[0]
    assert "Traceback" not in done.stdout + done.stderr and took < 15, took
