"""Waits that overlap (issue #14): the run-order plan on its own (plain objects), and whole conformance
runs in the simulated lane - overlap order against collection order and against pytest-randomly's
order, a window test selected alone, and the window faults still caught in overlap order."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from ckesc.bench.epochs import AFTER, INSIDE, PowerEpoch, unusable
from ckesc.protocol import catalogue as cat
from ckesc.session.schedule import LEAD_S, UNKNOWN_S, Plan

pytestmark = pytest.mark.xdist_group(__name__)  # its module-scoped runs are made once: its tests share one worker

W = cat.CONFIG_WINDOW_S


# ------------------------------------------------------------------------------------------ epochs
def _epoch(**kw):
    return PowerEpoch(**{"on_earliest": 10.0, "ready": 10.5, "node_id": 1, "bitrate": 500_000, "proven": True, **kw})


def test_an_epoch_serves_a_window_test_until_its_moment():
    e = _epoch()
    assert e.moment(INSIDE) == 10.0 + W - 1.0 and e.moment(AFTER) == 10.5 + W + 1.0
    assert unusable(e, INSIDE, now=50.0, node_id=1, bitrate=500_000) is None
    assert "past" in unusable(e, INSIDE, now=e.moment(INSIDE) + 0.01, node_id=1, bitrate=500_000)
    assert "past" in unusable(e, INSIDE, now=e.moment(INSIDE) - 1.0, node_id=1, bitrate=500_000, lead=2.0)
    assert unusable(e, AFTER, now=e.moment(AFTER) + 5.0, node_id=1, bitrate=500_000) is None  # acts late, still after


@pytest.mark.parametrize("change,why", [
    ({"proven": False}, "not proven"),
    ({"node_id": 2}, "node 2"),
    ({"bitrate": 250_000}, "250000"),
    ({"config": [("set_id", 20.0)]}, "set_id was sent inside its window"),
])
def test_what_makes_an_epoch_unusable(change, why):
    assert why in unusable(_epoch(**change), INSIDE, now=50.0, node_id=1, bitrate=500_000)


def test_a_command_sent_after_the_window_leaves_it_to_the_after_tests_only():
    """Set ID after the window (ignored by a right DUT) does not spoil the epoch for Set Baud after it;
    the same command inside the window does."""
    late = _epoch(config=[("set_id", 10.0 + W + 1.0)])
    assert unusable(late, AFTER, now=10.5 + W + 1.5, node_id=1, bitrate=500_000) is None
    early = _epoch(config=[("set_id", 30.0)])
    assert "inside its window" in unusable(early, AFTER, now=10.5 + W + 1.5, node_id=1, bitrate=500_000)


# ------------------------------------------------------------------------------------------ plan
KINDS = {"f": "filler", "c": "cycle", "i": "window-inside", "a": "window-after", "l": "last"}


def _plan(*names):
    """Items are names like 'f1@mod' (kind letter, number, module)."""
    return Plan(list(names), kind=lambda n: KINDS[n[0]], key=lambda n: f"{n.split('@')[1]}::{n.split('@')[0]}")


def _run(plan, durations, moment_of):
    """Drive the plan as the plugin does: returns the order and each item's start time."""
    order, now, item = [], 0.0, plan.first()
    while item is not None:
        order.append((item, round(now, 3)))
        now += durations.get(item, 1.0)
        plan.learn(item, durations.get(item, 1.0))
        item = plan.choose(now, lambda w, t: moment_of(w, t), lambda it: True)
    return order


def test_fillers_run_until_the_window_test_must_start():
    plan = _plan("c1@m", "i1@w", "f1@a", "f2@a", "f3@b", "l1@z")
    order = _run(plan, {"f1@a": 3.0, "f2@a": 3.0, "f3@b": 3.0}, lambda w, t: 20.0)
    names = [n for n, _ in order]
    assert names[0] == "f1@a"  # a filler first: the lane exists after it
    assert names.index("i1@w") > names.index("f2@a")
    assert names[-1] == "l1@z" and set(names) == {"c1@m", "i1@w", "f1@a", "f2@a", "f3@b", "l1@z"}
    start = dict(order)
    # every filler before the window test was expected (known or UNKNOWN_S) to end LEAD_S before its moment
    assert all(start[f] + 3.0 <= 20.0 for f in names[: names.index("i1@w")])
    # the power-cycling test waits until the window tests are done
    assert names.index("c1@m") > names.index("i1@w")


def test_an_unknown_filler_is_not_squeezed_in():
    plan = _plan("i1@w", "f1@a", "f2@b")
    order = _run(plan, {"f1@a": 1.0, "f2@b": 1.0}, lambda w, t: 1.0 + UNKNOWN_S + LEAD_S - 0.5)
    assert [n for n, _ in order] == ["f1@a", "i1@w", "f2@b"]  # f2 not seen yet: assumed UNKNOWN_S, it does not fit


def test_nothing_to_overlap_keeps_collection_order():
    plan = _plan("c1@m", "i1@w", "a1@w", "c2@m")
    assert not plan.overlapping
    assert [n for n, _ in _run(plan, {}, lambda w, t: 1e9)] == ["i1@w", "a1@w", "c1@m", "c2@m"]


def test_the_hint_commits_to_the_same_module_only_with_room_to_spare():
    plan = _plan("i1@w", "f1@a", "f2@a", "f3@b")
    first = plan.first()
    assert plan.hint(first, 1.0, lambda w, t: 100.0) == "f2@a"  # f2 shares a's set-up and surely fits
    assert plan.hint(first, 1.0, lambda w, t: 1.0 + UNKNOWN_S + LEAD_S + 1.0) == "i1@w"  # no room: the window test


def test_fillers_of_a_window_tests_module_come_last():
    plan = _plan("i1@w", "f1@w", "f2@a")
    assert plan.fillers == ["f2@a", "f1@w"]


# ------------------------------------------------------------------------------------------ whole runs
def _ckesc_run(tmp: Path, *args: str) -> dict:
    done = subprocess.run([sys.executable, "-m", "ckesc", "run", "-q", "--reports", str(tmp), *args],
                          capture_output=True, text=True, timeout=600)
    reports = sorted(tmp.glob("*/results.json"))
    assert reports, done.stdout[-3000:] + done.stderr[-3000:]
    return json.loads(reports[-1].read_text())


def _verdicts(doc: dict) -> dict[str, str]:
    return {r["nodeid"]: r["outcome"] for r in doc["results"]}


@pytest.fixture(scope="module")
def overlap_run(tmp_path_factory):
    return _ckesc_run(tmp_path_factory.mktemp("overlap"))


def test_overlap_order_shares_windows_and_changes_no_verdict(overlap_run, tmp_path):
    serial = _ckesc_run(tmp_path, "--order", "collection")
    assert _verdicts(overlap_run) == _verdicts(serial)
    assert overlap_run["coverage"] == serial["coverage"]  # the same requirements, judged the same
    assert set(_verdicts(overlap_run).values()) <= {"PASS", "OBSERVED"}
    assert overlap_run["info"]["order"] == "overlap" and "order" not in serial["info"]
    assert overlap_run["info"]["lane_seconds"] < serial["info"]["lane_seconds"] - 3 * W  # windows overlapped
    # the window tests of Set ID and Set Baud (the robustness section's malformed window writes share windows too, but
    # send no valid write whose moment could be read back)
    windows = [r for r in overlap_run["results"] if "window" in r["nodeid"] and r["section"] in ("4.4.18", "4.4.19")]
    assert len(windows) == 4
    for r in windows:
        seen = dict(r["observations"])
        assert seen["window"].startswith("shared: power-up at"), (r["nodeid"], seen["window"])
        assert r["lane_seconds"] < 20, r["nodeid"]  # the window elapsed while other tests ran
        sent = seen.get("sent at (s after power-on, at most)") or seen.get("sent at (s after power-on, at least)")
        assert sent is not None
        if "inside" in r["nodeid"]:
            assert float(sent) == pytest.approx(W - 1.0, abs=0.05)
        else:
            assert W + 1.0 <= float(sent) <= W + 1.0 + 10.0
    epochs = overlap_run["info"]["epochs"]
    assert epochs and all("error" not in e and e["traces"] for e in epochs)


@pytest.mark.slow  # a third whole run; CI keeps the plan's order against collection order (above)
def test_random_order_changes_no_verdict(overlap_run, tmp_path):
    """pytest-randomly shuffles the collection; the plan keeps its kinds apart, and every test's verdict
    is the same as in the plugin's own order."""
    pytest.importorskip("pytest_randomly")
    shuffled = _ckesc_run(tmp_path, "--", "-p", "randomly", "--randomly-seed", "1234")
    assert _verdicts(shuffled) == _verdicts(overlap_run)
    order = [r["nodeid"] for r in shuffled["results"]]
    assert order != [r["nodeid"] for r in overlap_run["results"]]  # it did run in another order


def test_a_window_test_alone_opens_its_own_window(tmp_path):
    doc = _ckesc_run(tmp_path, "4.4.18", "--", "-k", "just_inside")
    [r] = doc["results"]
    assert r["outcome"] == "PASS"
    assert dict(r["observations"])["window"].startswith("opened by this test")
    assert r["lane_seconds"] > W - 1.0  # it sat the window out, as before


@pytest.mark.parametrize("fault", [
    # CI: one of the three (a whole-window run each); the other two behind -m slow
    pytest.param("config_window_short", marks=pytest.mark.slow), "set_id_after_window",
    pytest.param("set_baud_after_window", marks=pytest.mark.slow)])
def test_window_faults_are_caught_in_overlap_order(tmp_path, fault):
    doc = _ckesc_run(tmp_path, "4.4.18", "4.4.19", "4.4.20", "--emulator-faults", fault)
    failed = {r["nodeid"].split("::")[1] for r in doc["results"] if r["outcome"] == "FAIL"}
    expect = {"config_window_short": "just_inside", "set_id_after_window": "set_id_after",
              "set_baud_after_window": "set_baud_after"}[fault]
    assert any(expect in name for name in failed), failed
    assert doc["info"]["order"] == "overlap"


# ------------------------------------------------------------------------------------------ shared cold boots
def test_cold_boot_groups_never_hold_two_writes_of_one_setting():
    names = ["b1@led", "b2@led", "b3@rot", "b4@rot", "b5@rot", "f1@x", "i1@w"]
    plan = Plan(names, kind=lambda n: {"b": "cold-boot", "f": "filler", "i": "window-inside"}[n[0]],
                key=lambda n: f"{n.split('@')[1]}::{n.split('@')[0]}", touches=lambda n: n.split("@")[1])
    assert plan.groups == [["b1@led", "b3@rot"], ["b2@led", "b4@rot"], ["b5@rot"]]
    assert plan.group_of("b1@led") == ["b1@led", "b3@rot"] and plan.group_of("b5@rot") is None
    order = [n for n, _ in _run(plan, {}, lambda w, t: 1e9)]
    assert order[-5:] == ["b1@led", "b3@rot", "b2@led", "b4@rot", "b5@rot"]  # each group's tests back to back


PERSISTENCE = ("4.4.20", "4.4.21", "4.4.22", "4.4.23")


def test_persistence_tests_share_power_cycles_and_keep_their_own_traces(overlap_run):
    boots = overlap_run["info"]["cold_boots"]
    assert len(boots) >= 2 and all("error" not in b and len(b["tests"]) > 1 for b in boots)
    by_id = {r["nodeid"]: r for r in overlap_run["results"]}
    for b in boots:
        for test in b["tests"]:
            r = by_id[test]
            assert r["outcome"] == "PASS", (test, r["message"])
            assert "write" in r["traces"] and r["traces"][""] != r["traces"]["write"]
            [shared] = [v for k, v in r["observations"] if k == "power cycle"]
            assert shared.startswith(b["name"]), shared


def test_a_test_failing_after_a_shared_cycle_is_judged_alone(tmp_path):
    """rotation_not_persisted: the direction test fails after the shared cycle, runs again alone and fails
    again (that is its verdict); so do the other sections' neighbour checks, which move the rotation and read it
    back after a power cycle (for the rule it breaks, 4.4.21-4); every other test keeps its faultless verdict."""
    doc = _ckesc_run(tmp_path, *PERSISTENCE, "--emulator-faults", "rotation_not_persisted")
    failed = {r["nodeid"].split("::")[1]: r for r in doc["results"] if r["outcome"] != "PASS" and r["outcome"] != "OBSERVED"}
    neighbours = {k for k, r in failed.items() if k.endswith("_leaves_the_other_settings")}
    assert set(failed) - neighbours == {"test_direction_persists_across_power_cycle"}, {k: v["message"][:200] for k, v in failed.items()}
    assert all("4.4.21-4" in failed[k]["requirements"] and "rotation" in failed[k]["message"] for k in neighbours)
    seen = dict(failed["test_direction_persists_across_power_cycle"]["observations"])
    assert "run again alone" in seen["after the shared power cycle"]
    assert doc["info"]["cold_boots"]


def test_a_persistence_test_alone_makes_its_own_power_cycle(tmp_path):
    doc = _ckesc_run(tmp_path, "4.4.22", "--", "-k", "intervals_persist")
    [r] = doc["results"]
    assert r["outcome"] == "PASS" and "write" not in r["traces"]
    assert not any(k == "power cycle" for k, _ in r["observations"])
    assert any(k == "power-up counter" for k, _ in r["observations"])  # its own proven cycle


def test_the_framing_capture_right_after_a_reopen_counts_no_held_report(tmp_path):
    """In collection order the framing section runs right after the R20 bus tests, whose reopen leaves the ESC's held
    reports to come back to back as the framing capture starts (R20: their transfer ids OBSERVE). Its F3 count takes
    them alone because the bus reader says they were held (``Rejoin.held_stretches``), not because it waits before its
    capture: without the reader's word this run FAILs F3 on the faultless emulator."""
    doc = _ckesc_run(tmp_path, "--order", "collection", "conformance/test_robustness_r20_bus.py", "4.1")
    order = [r["nodeid"] for r in doc["results"]]
    assert "r20_bus" in order[0] and "s4_1_framing" in order[-1]
    assert set(_verdicts(doc).values()) <= {"PASS", "OBSERVED"}, [(r["nodeid"], r["message"][:200]) for r in doc["results"]
                                                                  if r["outcome"] not in ("PASS", "OBSERVED")]
    f3 = [r for r in doc["results"] if "transfer_ids_count" in r["nodeid"]]
    assert len(f3) == 2 and all(r["outcome"] == "PASS" for r in f3)
