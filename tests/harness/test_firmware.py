"""The image under test (issue #37, ckesc/bench/firmware.py): where its expectation of 240 is found, the one rule
that judges 240's answer against it and the line a wrong image gets, a flash command that fails or hangs (killed
with what it started), and emulator images: the simulated lane runs what an image says, proven by its own 240
answer, and a series of 32 images whose 19th introduces a fault shows it from the 19th on."""

from __future__ import annotations

import hashlib
import time

import pytest
from firmware_images import FAULT, series

from ckesc.bench import firmware
from ckesc.bench.errors import PreflightError
from ckesc.bench.link import Link
from ckesc.bench.station import BenchOptions, build

IMAGE = "[esc_information]\nfirmware_date = \"2024-10-11\"\nprotocol_version = 21\nhardware_version = 3\n"
ANSWER = {"max_cells": 12, "max_current": 80.0, "hardware_version": 3, "protocol_version": 21, "firmware_year": 24,
          "firmware_month": 10, "firmware_day": 11}


def _binary(tmp_path, name="esc.bin"):
    path = tmp_path / name
    path.write_bytes(b"\x00\x01firmware")
    return path


def test_a_binary_is_proven_by_its_sidecar_then_firmware_toml_and_the_command_line_wins(tmp_path):
    image = _binary(tmp_path)
    with pytest.raises(PreflightError, match="nothing says what ESC Information"):
        firmware.load(str(image))
    (tmp_path / "firmware.toml").write_text(IMAGE.replace("2024-10-11", "2023-01-01"))
    assert firmware.load(str(image)).said_by == "firmware.toml"
    (tmp_path / "esc.bin.toml").write_text(IMAGE)
    loaded = firmware.load(str(image))
    assert (loaded.said_by, loaded.expected["firmware_date"], loaded.emulated) == ("esc.bin.toml", "2024-10-11", False)
    assert loaded.sha256 == hashlib.sha256(image.read_bytes()).hexdigest()
    forced = firmware.load(str(image), "protocol_version=22")
    assert (forced.said_by, forced.expected) == ("--expect-firmware", {"protocol_version": 22})


@pytest.mark.parametrize("text, said", [("firmware_date=24-10-11", "not a date"), ("colour=red", "not a field 240"),
                                        ("protocol_version", "not KEY=VALUE"), ("hardware_version=x", "not a whole number")])
def test_a_wrong_expectation_is_named(text, said):
    with pytest.raises(PreflightError, match=said):
        firmware.parse_expect(text)


def test_240_is_judged_field_by_field_and_a_wrong_image_is_one_line(tmp_path):
    (tmp_path / "esc.bin.toml").write_text(IMAGE)
    image = firmware.load(str(_binary(tmp_path)))
    assert "is running" in firmware.prove(image, ANSWER)
    older = {**ANSWER, "firmware_month": 9}
    assert firmware.mismatches(image.expected, firmware.answered(older)) == ["firmware_date"]
    with pytest.raises(PreflightError) as err:
        firmware.prove(image, older)
    assert str(err.value) == ("the image under test is not the one running: 240 says firmware_date=2024-09-11, "
                              "esc.bin.toml says firmware_date=2024-10-11")
    with pytest.raises(PreflightError, match="240 gave no answer"):
        firmware.prove(image, None)


@pytest.mark.realtime  # a hang is timed against the host's clock
def test_a_flash_that_fails_says_its_output_and_one_that_hangs_is_killed_with_its_children(tmp_path):
    (tmp_path / "esc.bin.toml").write_text(IMAGE)
    image = firmware.load(str(_binary(tmp_path)))
    with pytest.raises(PreflightError, match=r"exit status 3\): writing .*esc.bin no probe found$"):
        firmware.flash(image, "sh -c 'echo writing {image}; echo no probe found >&2; exit 3'")
    assert "wrote " + str(image.path) in firmware.flash(image, "sh -c 'echo wrote $0' {image}")
    start = time.monotonic()
    with pytest.raises(PreflightError, match="did not return within 0.5 s"):
        # a child that keeps the tool's output open must not hold the run past the limit
        firmware.flash(image, "sh -c 'sleep 30 & sleep 30'", timeout=0.5)
    assert time.monotonic() - start < 5


def test_the_simulated_lane_runs_an_emulator_image_and_proves_it_by_240(tmp_path):
    path = tmp_path / "sim.toml"
    path.write_text('options = ["report_timer=grid"]\n' + IMAGE.replace("2024-10-11", "2025-02-03"))
    station = build(BenchOptions(firmware=str(path)))
    try:
        said = station.prove(cycles_power=False)
        assert said and "firmware_date=2025-02-03" in said[0]
        assert station.played["report_timer"] == "grid"
        assert station.firmware["sha256"] == firmware.load(str(path)).sha256
    finally:
        station.close()
    wrong = build(BenchOptions(firmware=str(path), expect_firmware="firmware_date=2025-02-04"))
    try:
        with pytest.raises(PreflightError, match="240 says firmware_date=2025-02-03, --expect-firmware says"):
            wrong.prove(cycles_power=False)
    finally:
        wrong.close()


def _counters(path) -> dict:
    """Maintenance Information 241 option 2 of the emulated ESC running the image at ``path``."""
    station = build(BenchOptions(firmware=str(path)))
    try:
        station.prove(cycles_power=False)
        lane = station.open_lane()
        link = Link(lane, station.profile, node_id=1)
        link.discover()
        return dict(link.request("maintenance_information", {"option": 2}).response.fields)
    finally:
        station.close()


def test_a_series_of_32_images_shows_the_fault_from_the_19th_on(tmp_path):
    paths = series(tmp_path)
    assert len(paths) == 32 and (tmp_path / "images.txt").read_text().split() == [str(p) for p in paths]
    images = [firmware.load(str(p)) for p in paths]
    assert [i for i, im in enumerate(images, 1) if FAULT in im.faults] == list(range(19, 33))
    assert len({im.expected["firmware_date"] for im in images}) == 32
    good, bad = _counters(paths[17]), _counters(paths[18])
    assert good["power_ups"] >= 1 and good["stops"] == 0, good
    assert (bad["power_ups"], bad["stops"]) == (good["stops"], good["power_ups"]), (good, bad)


def test_every_report_names_the_image_in_the_same_words(tmp_path):
    from ckesc.reporting.compare import identity
    from ckesc.reporting.report import suite_properties, summary_text
    from ckesc.reporting.results import firmware_rows

    (tmp_path / "esc.bin.toml").write_text(IMAGE)
    image = firmware.load(str(_binary(tmp_path)))
    info = {"dut": "bus", "firmware": firmware.report(image, "flash {image}", "verified", ANSWER)}
    rows = dict(firmware_rows(info))
    assert rows["image SHA-256"] == image.sha256 and rows["flash output"] == "verified"
    assert rows["240 answered"] == "firmware_date=2024-10-11, protocol_version=21, hardware_version=3"
    assert identity(info)["image SHA-256"] == image.sha256
    assert suite_properties(info)["firmware.sha256"] == image.sha256
    assert f"image SHA-256: {image.sha256}" in summary_text([], info)
    assert firmware_rows({"dut": "emulator"}) == []
