"""Flashing through labgrid and per-bench images in rig files (issue #37, item 1; ckesc/bench/labgrid_flash.py),
for real on this machine: a labgrid environment file whose target has labgrid's own ``FlashromDriver`` on a local
``Flashrom`` resource, its ``flashrom`` tool (the env file's ``tools:``) a script that records what it was asked to
write, or fails, or hangs. ``ckesc run --flash-cmd labgrid`` writes the image through it before the bench proof and
proves it by 240; a flash that fails, hangs or finds no flashing driver is exit 2, one line, before any verdict. A rig
of two simulated benches flashes each bench's own image and proves each by its own 240 answer.

Without labgrid (the ``rig`` extra) the labgrid tests skip and say so; they never fail for it."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import time
from pathlib import Path

import pytest
from procs import CKESC
from procs import env as _env

from ckesc.bench import firmware
from ckesc.bench.errors import PreflightError
from ckesc.bench.station import BenchOptions, build
from ckesc.rigs import rig as rigs

needs_labgrid = pytest.mark.skipif(importlib.util.find_spec("labgrid") is None,
                                   reason='labgrid is not installed (pip install -e ".[rig]")')

IMAGE = '[esc_information]\nfirmware_date = "{date}"\nprotocol_version = 21\nhardware_version = 3\n'
#: a quick section: 4.4.26 asks 240, the image's own answer
SECTION = "4.4.26"


def _image(where: Path, name: str = "esc.toml", date: str = "2024-10-11") -> Path:
    path = where / name
    path.write_text(IMAGE.format(date=date))
    return path


def _lab(where: Path, tool_body: str, *, driver: str = "FlashromDriver: {}") -> Path:
    """A labgrid environment file: target ``esc`` with a local Flashrom resource and ``driver``; labgrid's
    ``flashrom`` tool is a script (``tool_body``: sh lines; ``$2`` is the image's path) that records its arguments
    in ``flashed.txt`` first."""
    tool = where / "flashrom"
    tool.write_text(f'#!/bin/sh\necho "$@" >> "{where / "flashed.txt"}"\n{tool_body}\n')
    tool.chmod(0o755)
    env_file = where / "env.yaml"
    env_file.write_text("targets:\n  esc:\n    resources:\n      Flashrom:\n        programmer: ch341a_spi\n"
                        f"    drivers:\n      {driver}\ntools:\n  flashrom: {tool}\n")
    return env_file


def _ckesc(tmp: Path, *args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run([*CKESC, *args], cwd=tmp, env=_env(tmp), capture_output=True, text=True, timeout=timeout)


def _flashed(where: Path) -> list[str]:
    path = where / "flashed.txt"
    return path.read_text().splitlines() if path.exists() else []


# ----------------------------------------------------------------------------------------- --flash-cmd labgrid
@needs_labgrid
def test_labgrids_flashrom_driver_writes_the_image_then_240_proves_it(tmp_path):
    image = _image(tmp_path)
    env_file = _lab(tmp_path, 'echo "flashrom: wrote $2"')
    done = _ckesc(tmp_path, "run", "-q", "--firmware", str(image), "--flash-cmd", "labgrid", "--labgrid-env",
                  str(env_file), "--reports", str(tmp_path / "reports"), SECTION)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    # labgrid's driver ran its tool on the image's own path with the resource's programmer
    assert _flashed(tmp_path) == [f"-w {image} -p ch341a_spi"]
    fw = json.loads((tmp_path / "reports" / "latest" / "results.json").read_text())["info"]["firmware"]
    assert fw["flash_cmd"] == "labgrid" and fw["sha256"] == firmware.load(str(image)).sha256
    assert fw["flash_output"] == f"labgrid: esc.toml written by FlashromDriver of target esc of {env_file}"
    assert fw["answered"].startswith("firmware_date=2024-10-11")


@needs_labgrid
@pytest.mark.realtime  # `ckesc emulate` behind socketcand, its power switched over HTTP
def test_one_labgrid_target_switches_the_power_and_flashes_the_image_of_a_bus_bench(tmp_path):
    """--power labgrid and --flash-cmd labgrid through the same env file's target: the image written, the DUT power
    cycled by labgrid's NetworkPowerDriver and proven by its counter, then 240 proves the image (``ckesc emulate``
    runs it)."""
    pytest.importorskip("requests", reason="labgrid's REST power models need requests (comes with labgrid)")
    from labgrid_lab import PowerSwitch
    from procs import Emulator

    image = _image(tmp_path, date="2025-02-03")
    emu = Emulator(tmp_path, "--firmware", str(image))
    switch = PowerSwitch(emu.control)
    try:
        env_file = _lab(tmp_path, 'echo "flashrom: wrote $2"', driver="FlashromDriver: {}\n      NetworkPowerDriver: {}")
        env_file.write_text(env_file.read_text().replace(
            "    drivers:", f"      NetworkPowerPort:\n        model: simplerest\n        host: '{switch.url}'\n"
            "        index: 0\n    drivers:"))
        profile = tmp_path / "bench.toml"
        profile.write_text('[dut]\nname = "bench"\n[capabilities]\nled = true\nmotor = true\n'
                           "[timing]\nerror_s = 0.002\nboot_s = 0.5\noff_s = 0.5\n")
        done = _ckesc(tmp_path, "run", "-q", "--dut", "bus", "--can-interface", "socketcand", "--can-channel", "can0",
                      "--can-config", "host=127.0.0.1", "--can-config", f"port={emu.port}", "--profile", str(profile),
                      "--power", "labgrid", "--labgrid-env", str(env_file), "--firmware", str(image), "--flash-cmd",
                      "labgrid", "--reports", str(tmp_path / "reports"), "--", "-k", "power_up_counter_counts_each_power_up")
    finally:
        switch.close()
        emu.close()
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert _flashed(tmp_path) == [f"-w {image} -p ch341a_spi"]
    assert switch.switched[:2] == ["off", "on"], switch.switched  # the flash's power cycle, proven
    info = json.loads((tmp_path / "reports" / "latest" / "results.json").read_text())["info"]
    assert info["firmware"]["answered"].startswith("firmware_date=2025-02-03")
    assert "NetworkPowerDriver of target esc" in info["power_labgrid"]


LABGRID_FAILURES = [
    pytest.param('echo "no programmer found" >&2; exit 3', "FlashromDriver: {}", {},
                 ["returned non-zero exit status 3", "no programmer found"], id="tool-fails"),
    pytest.param("sleep 30 & sleep 30", "FlashromDriver: {}", {"flash_timeout": 1.5},
                 ["did not return within 1.5 s", "--flash-timeout"], id="tool-hangs"),
    pytest.param("", "NetworkPowerDriver: {}", {}, ["target esc", "has no flashing driver", "FlashromDriver"],
                 id="no-flash-driver"),
    pytest.param("", "FlashromDriver: {}", {"labgrid_target": "other"}, ["no target 'other'"], id="no-target"),
]


@needs_labgrid
@pytest.mark.realtime  # a hang is timed against the host's clock
@pytest.mark.parametrize("tool, driver, options, said", LABGRID_FAILURES)
def test_a_labgrid_flash_that_fails_hangs_or_has_no_driver_is_one_preflight_line(tmp_path, tool, driver, options, said):
    image = _image(tmp_path)
    env_file = _lab(tmp_path, tool, driver=driver)
    if driver.startswith("NetworkPowerDriver"):  # a target with power but nothing to flash with
        env_file.write_text(env_file.read_text().replace(
            "Flashrom:\n        programmer: ch341a_spi", "NetworkPowerPort:\n        model: simplerest\n"
            "        host: 'http://127.0.0.1:1/{index}/{value}'\n        index: 0"))
    station = build(BenchOptions(firmware=str(image), flash_cmd="labgrid", labgrid_env=str(env_file), **options))
    start = time.monotonic()
    try:
        with pytest.raises(PreflightError) as caught:
            station.prove(cycles_power=False)
    finally:
        station.close()
    text = str(caught.value)
    assert "\n" not in text and text.startswith("flash of esc.toml:"), text
    assert all(s in text for s in said), text
    assert station.firmware is None  # no verdict on an image that was not written
    assert time.monotonic() - start < 20


def test_flash_cmd_labgrid_needs_the_environment_file(tmp_path):
    image = _image(tmp_path)
    for options, said in (({}, "--flash-cmd labgrid needs --labgrid-env FILE"),
                          ({"labgrid_env": str(tmp_path / "none.yaml")}, "none.yaml: no such file")):
        with pytest.raises(PreflightError, match=said):
            build(BenchOptions(firmware=str(image), flash_cmd="labgrid", **options))
    # the env file is for labgrid power, flashing or the bus-fault relay; given for none it is a mistake
    with pytest.raises(PreflightError, match="--labgrid-env is for --power labgrid, --flash-cmd labgrid or "
                                             "--bus-fault-cmd labgrid"):
        build(BenchOptions(dut="bus", can_interface="virtual", labgrid_env=str(image)))


def test_the_whole_failure_is_exit_2_and_one_line_before_any_verdict(tmp_path):
    """As a new user meets it: the tool's own complaint on the one line, no test run, no report of a verdict."""
    if importlib.util.find_spec("labgrid") is None:
        pytest.skip('labgrid is not installed (pip install -e ".[rig]")')
    image = _image(tmp_path)
    env_file = _lab(tmp_path, 'echo "chip not found" >&2; exit 1')
    done = _ckesc(tmp_path, "run", "-q", "--firmware", str(image), "--flash-cmd", "labgrid", "--labgrid-env",
                  str(env_file), "--reports", str(tmp_path / "reports"), SECTION)
    assert done.returncode == 2, done.stdout[-3000:] + done.stderr[-3000:]
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and "flash of esc.toml" in lines[0] and "chip not found" in lines[0], done.stderr
    assert "passed" not in done.stdout and "failed" not in done.stdout, done.stdout


# ----------------------------------------------------------------------------------------- rig files
def test_a_rig_bench_sets_its_own_image_flash_command_and_expectation():
    rig = rigs.parse("""
[bench.a]
firmware = "images/a.toml"
flash_cmd = "flash-tool {image}"
flash_timeout = 30
expect_firmware = { firmware_date = "2024-10-11", protocol_version = 21 }

[bench.b]
""", "/lab/rigs/line.toml")
    a = rig.benches["a"].options()
    assert a["firmware"] == "/lab/rigs/images/a.toml" and a["flash_cmd"] == "flash-tool {image}"
    assert a["flash_timeout"] == 30 and a["expect_firmware"] == "firmware_date=2024-10-11,protocol_version=21"
    assert rig.benches["a"].argv()[-8:] == ["--firmware", "/lab/rigs/images/a.toml", "--flash-cmd", "flash-tool {image}",
                                            "--flash-timeout", "30.0", "--expect-firmware",
                                            "firmware_date=2024-10-11,protocol_version=21"]
    assert "firmware" not in rig.benches["b"].options()
    with pytest.raises(rigs.RigError, match="flash_timeout"):
        rigs.parse("[bench.a]\nflash_timeout = 0\n", "/lab/rigs/line.toml")


@pytest.mark.realtime  # a batch of pytest-xdist workers
def test_a_rig_of_two_simulated_benches_flashes_and_proves_each_benchs_own_image(tmp_path):
    pytest.importorskip("xdist", reason="the batch runs through pytest-xdist: pip install -e '.[rig]'")
    images = tmp_path / "images"
    images.mkdir()
    _image(images, "a.toml", "2024-10-11")
    _image(images, "b.toml", "2025-02-03")
    flash = "sh -c 'echo \\\"flashing $0\\\"; echo \\\"$0\\\" >> flashed.txt' {image}"
    (tmp_path / "rig.toml").write_text(
        f'[bench.a]\nfirmware = "images/a.toml"\nflash_cmd = "{flash}"\n\n'
        '[bench.b]\nfirmware = "images/b.toml"\nexpect_firmware = { firmware_date = "2025-02-03" }\n')
    done = _ckesc(tmp_path, "run", "--rig", "rig.toml", "--reports", str(tmp_path / "reports"), SECTION, timeout=600)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    batch = (tmp_path / "reports" / "latest").resolve()
    fw = {b: json.loads((batch / b / "results.json").read_text())["info"]["firmware"] for b in ("a", "b")}
    assert fw["a"]["image"] == str(images / "a.toml") and fw["b"]["image"] == str(images / "b.toml")
    assert fw["a"]["answered"].startswith("firmware_date=2024-10-11")
    assert fw["b"]["answered"] == "firmware_date=2025-02-03" and fw["b"]["expected"].endswith("(--expect-firmware)")
    assert fw["a"]["flash_output"] == f"flashing {images / 'a.toml'}" and fw["b"]["flash_cmd"] == ""
    assert (tmp_path / "flashed.txt").read_text().split() == [str(images / "a.toml")]  # b: the emulator's builtin
    assert fw["a"]["sha256"] != fw["b"]["sha256"]
