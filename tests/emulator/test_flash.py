"""The emulator's flash file: a round trip, atomic writes, and unreadable files refused, never replaced."""

from __future__ import annotations

import json
import os

import can
import pytest

from ckesc.emulator import EscConfig, factory_nvm, sim_bus
from ckesc.emulator import flash as flash_mod
from ckesc.emulator.emulated_bench import EmulatedBench
from ckesc.emulator.flash import FORMAT, FlashError, FlashStore


def _slots() -> dict:
    a = factory_nvm(EscConfig(node_id=3))
    b = factory_nvm(EscConfig(node_id=0x7D))
    a.update(node_id=9, throttle_channel=17, rotation=1, total_run_time=12.375, power_ups=65535)
    a["records"]["mos"].update(t_max=88, times=4, time=321)
    return {0: a, 1: b}


@pytest.fixture
def store(tmp_path):
    return FlashStore(tmp_path / "bench" / "esc-flash.json")


def test_missing_file_is_factory_state(store):
    assert store.load() == {}
    assert not store.path.exists()


def test_round_trip(store):
    slots = _slots()
    store.save(slots)  # creates the folder
    assert store.load() == slots
    doc = json.loads(store.path.read_text())
    assert doc["format"] == FORMAT and set(doc["slots"]) == {"0", "1"}
    slots[0]["node_id"] = 10
    store.save(slots)
    assert store.load()[0]["node_id"] == 10
    assert sorted(p.name for p in store.path.parent.iterdir()) == [store.path.name]


def _leftovers(store) -> list[str]:
    return sorted(p.name for p in store.path.parent.iterdir() if p.name != store.path.name)


@pytest.mark.parametrize("where", ["write", "fsync", "replace"])
@pytest.mark.parametrize("exc", [OSError("disk gone"), KeyboardInterrupt()], ids=["OSError", "KeyboardInterrupt"])
def test_a_crash_mid_write_leaves_the_old_file_and_no_temp_file(store, monkeypatch, where, exc):
    old = _slots()
    store.save(old)
    before = store.path.read_bytes()
    new = _slots()
    new[0]["node_id"] = 42

    if where == "write":  # half the bytes reach the temp file, then the process dies
        real_fdopen = os.fdopen

        class Dying:
            def __init__(self, fh):
                self.fh = fh

            def __enter__(self):
                return self

            def __exit__(self, *a):
                self.fh.close()

            def write(self, data):
                self.fh.write(data[: len(data) // 2])
                self.fh.flush()
                raise exc

        monkeypatch.setattr(flash_mod.os, "fdopen", lambda fd, mode: Dying(real_fdopen(fd, mode)))
    else:
        def boom(*args):
            raise exc

        monkeypatch.setattr(flash_mod.os, where, boom)

    with pytest.raises(type(exc)):
        store.save(new)
    monkeypatch.undo()
    assert store.path.read_bytes() == before
    assert store.load() == old
    assert _leftovers(store) == []


def test_the_temp_file_is_renamed_in_place_after_fsync(store, monkeypatch):
    """Same folder (an atomic rename), data fsync'ed before the rename, the folder after it."""
    calls = []
    real_replace, real_fsync = os.replace, os.fsync

    def replace(src, dst):
        calls.append(("replace", os.path.dirname(src) == os.path.dirname(str(dst)), dst == store.path))
        return real_replace(src, dst)

    def fsync(fd):
        calls.append(("fsync", os.path.isdir(f"/proc/self/fd/{fd}") if os.path.exists("/proc/self/fd") else None))
        return real_fsync(fd)

    monkeypatch.setattr(flash_mod.os, "replace", replace)
    monkeypatch.setattr(flash_mod.os, "fsync", fsync)
    store.save(_slots())
    assert [c[0] for c in calls] == ["fsync", "replace", "fsync"]
    assert calls[1] == ("replace", True, True)
    if calls[0][1] is not None:
        assert (calls[0][1], calls[2][1]) == (False, True)  # the file, then its folder


UNREADABLE = {
    "truncated json": b'{"format": "ckesc-emulator-flash/1", "slots": {"0": {"node_id": 3',
    "empty": b"",
    "foreign json": b'{"hello": "world"}',
    "json list": b"[1, 2, 3]",
    "other format": b'{"format": "ckesc-emulator-flash/0", "slots": {}}',
    "slots not a mapping": b'{"format": "ckesc-emulator-flash/1", "slots": [1, 2]}',
}


@pytest.mark.parametrize("content", UNREADABLE.values(), ids=UNREADABLE.keys())
def test_an_unreadable_file_is_refused_and_kept(store, content):
    store.path.parent.mkdir(parents=True)
    store.path.write_bytes(content)
    with pytest.raises(FlashError, match="move it away to start from factory state") as err:
        store.load()
    assert str(store.path) in str(err.value)
    with pytest.raises(FlashError):
        EmulatedBench([1], flash=store.path)
    assert store.path.read_bytes() == content  # never overwritten
    assert _leftovers(store) == []


MORE_UNREADABLE = {
    "binary garbage": bytes(range(256)),  # not UTF-8
    "slot key not a number": b'{"format": "ckesc-emulator-flash/1", "slots": {"a": {}}}',
    "slot not a table": b'{"format": "ckesc-emulator-flash/1", "slots": {"0": 5}}',
}


@pytest.mark.parametrize("content", MORE_UNREADABLE.values(), ids=MORE_UNREADABLE.keys())
def test_more_corrupt_files_raise_flash_error(store, content):
    store.path.parent.mkdir(parents=True)
    store.path.write_bytes(content)
    with pytest.raises(FlashError):
        store.load()


def test_opening_a_sim_bus_on_a_corrupt_flash_fails_and_keeps_the_file(tmp_path):
    path = tmp_path / "esc-flash.json"
    path.write_text("this is not json")
    channel = "test_flash-corrupt-bus"
    with pytest.raises(FlashError, match="not a flash file"):
        can.Bus(interface="ckesc-sim", channel=channel, nodes=[1], flash_path=str(path), ignore_config=True)
    sim_bus.discard(channel)
    assert path.read_text() == "this is not json"


def test_a_bench_persists_on_power_off_and_only_when_changed(tmp_path):
    path = tmp_path / "esc-flash.json"
    bench = EmulatedBench([1, 2], flash=path)
    bench.power_on(0.0)
    bench.power_off(1.0)
    stored = FlashStore(path).load()
    assert [stored[s]["node_id"] for s in (0, 1)] == [1, 2] and stored[0]["power_ups"] == 1
    mtime = path.stat().st_mtime_ns
    os.utime(path, ns=(0, 0))
    bench.persist()  # nothing changed since
    assert path.stat().st_mtime_ns == 0 != mtime
    again = EmulatedBench([5, 6], flash=path)  # the flash's node ids win over the factory ones
    assert [e.node_id for e in again.escs] == [1, 2]
    again.power_on(2.0)
    again.power_off(3.0)
    assert FlashStore(path).load()[1]["power_ups"] == 2
