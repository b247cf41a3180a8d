"""A simulated soak made faster must read the same bus: two short soaks' every frame (the trace, candump's lines with
their times) and every finding (time, watch, rules, message), as a digest pinned when issue #35 took the soak's
per-frame waste out (the revision before it, cb4704d, gives the same digests; the fault case's pinned again when the
simulated lane took SocketCAN's acknowledgement, issue #36: ``CKESC_SIM_ACK=0`` still gives the old one). One faultless at the default 400 Hz
stream with a flight controller's traffic (the bench's own frames, other nodes', the DUT's answers to both), one with
an emulator fault found at 50 Hz in RawCommand_12b with the motor spun up and down (the throttle changing, a finding
and its frames). A change that moves a frame or a finding fails here: if it is meant (the emulator or a watch changed
on purpose), check the new findings and pin the new digest."""

from __future__ import annotations

import hashlib
import io
import json

import pytest

from ckesc.bench.station import BenchOptions
from ckesc.soak import runner, split

CASES = {
    "faultless, 400 Hz, foreign traffic": (BenchOptions(foreign_traffic="ardupilot"), {"duration_s": 12.0},
                                           0, "83c900519ba2fef775cbced542473e6d192858a18b449c75e985a94a46144ace"),
    # the simulated world's fast path (issue #35's speed: no other node on the bus, frames read without a
    # can.Message), faultless and with a soak fault that resets the ESC mid-stream (pinned on 0f32086)
    "faultless, 400 Hz, the host alone with the ESC": (BenchOptions(), {"duration_s": 12.0},
                                                       0, "b2e69de75c786ee3d93549a7d3c952cab1daa5c16c4071dd825f3df2b14628dc"),
    "reset_after_streaming at 5 s, 400 Hz": (BenchOptions(emulator_faults="reset_after_streaming=5"), {"duration_s": 12.0},
                                             # (2 findings with the lane's acknowledgement: the GET_ESC_ID asked
                                             # while the ESC reboots is held and answered at its boot, R20)
                                             2, "e92c51ff3568f4b1aa55647db31fde9816ff44d46d0c55239fc94c8813c967f1"),
    "report_interval_wrong, 50 Hz 12b, throttle profile": (
        BenchOptions(emulator_faults="report_interval_wrong", allow_motor_spin=True),
        {"duration_s": 40.0, "rate_hz": 50.0, "format": "12b", "throttle": ((0.0, 0), (10.0, 200), (25.0, 0))},
        # (with the lane's acknowledgement, issue #36, the ESC's reports begin on another phase and no frame the host
        # did not hear counts its transfer ids; discovery asks no query again while its last waits unacknowledged,
        # so one GET_ESC_ID fewer precedes the soak: the same finding, at the same time, with the same words)
        1, "9d43bac3d1da7c51e8ee692d0bb4c63360ffcd6af1742e5f6880cfca93be4e4e"),
}


def soak_digest(tmp_path, bench: BenchOptions, options: dict) -> tuple[int, str]:
    outcome = runner.run(bench, runner.SoakOptions(reports=str(tmp_path), quiet=True, **options), out=io.StringIO())
    assert outcome.where is not None
    doc = json.loads((outcome.where / "results.json").read_text())
    h = hashlib.sha256()
    for log in sorted(outcome.where.glob("*.log")):  # the rolling trace and each finding's frames
        h.update(log.name.encode() + b"\n" + log.read_bytes())
    h.update(json.dumps([[f["t_s"], f["watch"], f["rules"], f["message"]] for f in doc["findings"]]).encode())
    h.update(json.dumps(doc["frames"]).encode())
    return outcome.findings, h.hexdigest()


@pytest.mark.parametrize("processes", ["1", "2"])
@pytest.mark.parametrize("case", CASES)
def test_a_short_simulated_soak_reads_the_frames_and_finds_what_it_did_before(tmp_path, monkeypatch, case, processes):
    """In one process and in two (the world's frames handed over in batches of 256 here, so that a short soak's
    frames cross in many)."""
    monkeypatch.setattr(split, "BATCH_FRAMES", 256)
    bench, options, findings, pinned = CASES[case]
    found, digest = soak_digest(tmp_path, bench, {**options, "processes": processes})
    assert found == findings
    assert digest == pinned, f"{case}: the soak's frames or findings changed (digest {digest})"
