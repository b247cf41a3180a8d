"""``ckesc run --firmware IMAGE --flash-cmd "CMD {image}"`` tried as a new user meets it (issue #37), as real
processes: a flash command that fails, one that hangs past ``--flash-timeout``, and an image whose 240 answer
differs from the one expected are each exit 2, one line on stderr, no verdict and no report, within seconds; a good
image runs and its SHA-256 is in results.json. On the emulator (``--dut emulator``: the image is an emulator image,
no flash tool needed), and on a real bus against ``ckesc emulate --firmware`` as a stand-in for one's own ESC: the
flash is followed by the proven power cycle that starts the image, and 240 proves it."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "harness"))
from procs import CKESC, Emulator, one_line_exit_2  # noqa: E402
from procs import env as _env  # noqa: E402

pytestmark = pytest.mark.realtime  # real processes timed against the wall clock

ROOT = Path(__file__).resolve().parents[2]
RELEASE = ROOT / "fixtures" / "firmware" / "release-1.0.toml"
#: what a mistake may take, the interpreter's start and pytest's collection included
WITHIN_S = 20.0


def _run(tmp: Path, *args: str) -> tuple[subprocess.CompletedProcess, float]:
    start = time.monotonic()
    done = subprocess.run([*CKESC, "run", "-q", "--reports", str(tmp / "reports"), *args], cwd=tmp, env=_env(tmp),
                          capture_output=True, text=True, timeout=120)
    return done, time.monotonic() - start


def _one_line_exit_2(done: subprocess.CompletedProcess, took: float, tmp: Path, *phrases: str) -> str:
    return one_line_exit_2(done, took, tmp, *phrases, within=WITHIN_S)


def test_a_flash_command_that_fails_is_exit_2_before_any_verdict(tmp_path):
    done, took = _run(tmp_path, "--firmware", str(RELEASE), "--flash-cmd", "sh -c 'echo no probe >&2; exit 1'", "4.4.26")
    _one_line_exit_2(done, took, tmp_path, "flash of release-1.0.toml", "failed (exit status 1): no probe")


def test_a_flash_command_that_hangs_is_killed_at_its_limit(tmp_path):
    done, took = _run(tmp_path, "--firmware", str(RELEASE), "--flash-cmd", "sleep 60", "--flash-timeout", "1", "4.4.26")
    _one_line_exit_2(done, took, tmp_path, "'sleep 60' did not return within 1 s", "--flash-timeout")


def test_an_image_whose_240_answer_differs_is_not_the_one_running(tmp_path):
    done, took = _run(tmp_path, "--firmware", str(RELEASE), "--expect-firmware", "firmware_date=2024-11-02", "4.4.26")
    _one_line_exit_2(done, took, tmp_path, "the image under test is not the one running: 240 says "
                     "firmware_date=2024-10-11, --expect-firmware says firmware_date=2024-11-02")


def test_a_good_image_runs_and_results_json_holds_its_sha256(tmp_path):
    done, _ = _run(tmp_path, "--firmware", str(RELEASE), "--flash-cmd", "echo flashing {image}", "4.4.26")
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr
    info = json.loads((tmp_path / "reports" / "latest" / "results.json").read_text())["info"]
    assert info["firmware"]["sha256"] == hashlib.sha256(RELEASE.read_bytes()).hexdigest()
    assert info["firmware"]["flash_output"] == f"flashing {RELEASE}"
    assert info["firmware"]["answered"] == "firmware_date=2024-10-11, protocol_version=21, hardware_version=3"
    summary = (tmp_path / "reports" / "latest" / "summary.txt").read_text()
    assert f"image SHA-256: {info['firmware']['sha256']}" in summary


def test_on_a_bus_the_flash_is_followed_by_a_proven_power_cycle_and_240_proves_the_image(tmp_path):
    profile = tmp_path / "mine.toml"
    profile.write_text('[dut]\nname = "my ESC"\n[timing]\nboot_s = 0.5\noff_s = 0.5\n')
    binary = tmp_path / "esc-1.0.bin"
    binary.write_bytes(b"\x7fbuild 1.0")
    # what the vendor's build says 240 answers: release-1.0's, which the stand-in ESC runs
    (tmp_path / "esc-1.0.bin.toml").write_text('[esc_information]\nfirmware_date = "2024-10-11"\nprotocol_version = 21\n')
    emu = Emulator(tmp_path, "--firmware", str(RELEASE))  # the stand-in ESC runs release-1.0
    try:
        done, _ = _run(tmp_path, *emu.bench(profile), "--firmware", str(binary), "--flash-cmd", "echo wrote {image}",
                       "4.4.26")
        assert done.returncode == 0, done.stdout[-3000:] + done.stderr
        info = json.loads((tmp_path / "reports" / "latest" / "results.json").read_text())["info"]
        assert info["firmware"]["sha256"] == hashlib.sha256(binary.read_bytes()).hexdigest()
        assert any("power switch (command) proven" in line for line in info["bench"]), info["bench"]
        (tmp_path / "esc-1.0.bin.toml").write_text('[esc_information]\nfirmware_date = "2024-11-02"\n')
        shutil.rmtree(tmp_path / "reports")
        done, took = _run(tmp_path, *emu.bench(profile), "--firmware", str(binary), "--flash-cmd", "echo wrote {image}",
                          "4.4.26")
        _one_line_exit_2(done, took, tmp_path, "240 says firmware_date=2024-10-11, esc-1.0.bin.toml says "
                         "firmware_date=2024-11-02")
    finally:
        emu.close()
