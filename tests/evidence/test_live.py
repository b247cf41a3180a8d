"""The bus rules in the background of a suite run: a test during which the DUT's traffic breaks a rule
fails with the frames quoted and the rule's requirement ids in results.json, and ``ckesc selftest``
counts those ids as cited. Each case runs one conformance module against the emulator."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from ckesc.selftest import run_suite

#: section 4.4.26 (and 4.1's check of its answer): none looks at tail bytes (the robustness section's ESC Information
#: case sends malformed frames on purpose and judges R17 first)
MODULE = "esc_information and not robustness"


def suite(tmp_path, *args: str) -> tuple[subprocess.CompletedProcess, list[dict]]:
    done = subprocess.run([sys.executable, "-m", "pytest", "--pyargs", "conformance", "-q", "-p", "no:cacheprovider",
                           "-k", MODULE, "--ckesc-reports", str(tmp_path), *args], capture_output=True, text=True,
                          env={**os.environ, "PYTHONHASHSEED": "0"}, timeout=300)
    return done, json.loads((tmp_path / "latest" / "results.json").read_text())["results"]


def test_a_bus_rule_broken_during_a_test_fails_it(tmp_path):
    done, results = suite(tmp_path, "--emulator-faults", "tail_toggle_set")
    assert done.returncode == 1
    assert "[bus rules F2 4.1.3-toggle]" in done.stdout and "toggle=1" in done.stdout
    assert results
    for r in results:
        assert r["outcome"] == "FAIL" and r["bus_rules"] == ["F2", "4.1.3-toggle"]
        assert r["message"].startswith("[bus rules F2 4.1.3-toggle]") and "#" in r["message"]  # the frames, candump style


def test_the_faultless_emulator_passes(tmp_path):
    done, results = suite(tmp_path)
    assert done.returncode == 0, done.stdout[-2000:]
    assert results and all(r["outcome"] == "PASS" and r["bus_rules"] == [] for r in results)


def test_selftest_counts_the_ids_a_bus_rule_failure_cites():
    run = run_suite("tail_toggle_set", ["-k", MODULE])
    assert run.failing and run.ok, run.problem
    assert all("F2" in ids for _, ids in run.failing)
