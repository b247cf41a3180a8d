"""The bus reader's events (:class:`ckesc.evidence.events.ReaderEvents`, issue #35 item 2): what the soak's watches
take instead of keeping the state again. A reset's sign comes before the report that shows it; the soak finds the
reset the bus rules find, at the same frame and in the same words; and the reader's state stays the same size over a
run three times as long (memory flat over hours: every per-frame keeper is a counter, a bounded cache or a fixed-bin
histogram)."""

from __future__ import annotations

from typing import Any

from ckesc.evidence.events import ReaderEvents
from ckesc.evidence.rules import BusRules
from ckesc.protocol.frame import WireFrame, encode
from ckesc.protocol.ids import Kind
from ckesc.soak.monitor import Monitor
from ckesc.soak.watch import WatchConfig

HOST, NODE = 0, 1
INTERVALS = {"msg1": 0.020, "msg2": 0.100, "msg3": 0.500}


def traffic(seconds: float, reset_at: float | None = None) -> list[WireFrame]:
    """A soak's bus: the host's stream at 50 Hz, GET_ESC_ID once a second and its answer, 241 every 5 s, and the ESC's
    reports; with ``reset_at``, every report stops for 300 ms there and its transfer ids start again at 0."""
    out: list[WireFrame] = []
    tid: dict[str, int] = {}

    def nxt(key: str) -> int:
        tid[key] = tid.get(key, -1) + 1
        return tid[key] % 32

    for k in range(int(seconds / 0.02)):
        out.append(encode("raw_command_14b", {"channels": [0] * 4}, source=HOST, transfer_id=nxt("stream"), timestamp=k * 0.02))
    fields = {"msg1": {"speed": 0, "pwm": 0, "status": 0}, "msg2": {"voltage": 1200, "current": 0, "temperature": 30},
              "msg3": {"mos_t": 30, "cap_t": 30, "motor_t": 30, "mcu_t": 30}}
    for i, (name, interval) in enumerate(INTERVALS.items()):
        t, origin, n = 0.0, 0.001 + 0.002 * i, 0
        while (t := origin + n * interval) < seconds:
            if reset_at is not None and origin < reset_at <= t:
                origin, n, tid[name] = reset_at + 0.3 + 0.002 * i, 0, -1
                continue
            out.append(encode(name, fields[name], source=NODE, transfer_id=nxt(name), timestamp=t))
            n += 1
    for s in range(int(seconds)):
        q = nxt("q")
        out.append(encode("get_esc_id", {"option": 0}, source=HOST, transfer_id=q, layout="query", timestamp=s + 0.007))
        out.append(encode("get_esc_id", {"node_id": NODE, "throttle_channel": 1}, source=NODE, transfer_id=q,
                          layout="reply", timestamp=s + 0.0095))
        if s % 5 == 2:
            q = nxt("241")
            out.append(encode("maintenance_information", {"option": 2}, source=HOST, destination=NODE, transfer_id=q,
                              timestamp=s + 0.5))
            out.append(encode("maintenance_information", {"power_ups": 7, "stops": 0, "fault_code": 0, "option": 2},
                              kind=Kind.RESPONSE, source=NODE, destination=HOST, transfer_id=q,
                              layout="response_option_2", timestamp=s + 0.504))
    return sorted(out, key=lambda w: w.timestamp)


def rules() -> BusRules:
    r = BusRules(power_known=True, complete=True)
    r.stated(NODE, INTERVALS, "the test's")
    return r


def feed(r: BusRules, frames: list[WireFrame]) -> list:
    out = []
    for w in frames:
        out += r.feed(w.arbitration_id, w.data, w.timestamp, own=(w.arbitration_id & 0x7F) == HOST)
    return out


class Told(ReaderEvents):
    def __init__(self) -> None:
        self.said: list[tuple[Any, ...]] = []

    def report(self, ts, node, name, restarted):
        self.said.append(("report", ts, name, restarted))

    def reset(self, ts, node, sign, signs):
        self.said.append(("reset", ts, sign.what, signs.same))


def test_a_resets_sign_comes_before_the_report_that_shows_it_and_every_report_after_it_restarted():
    r, told = rules(), Told()
    r.events = told
    assert not feed(r, traffic(5.0))
    assert told.said and not any(e[0] == "reset" or e[3] for e in told.said)  # a faultless ESC: no sign, no restart
    r, told = rules(), Told()
    r.events = told
    found = [v for v in feed(r, traffic(5.0, reset_at=2.0)) if v.check == "reset"]
    resets = [i for i, e in enumerate(told.said) if e[0] == "reset"]
    assert len(found) == len(resets) == 3  # each report's gap: one reset, its other two signs counted with it
    assert [told.said[i][3] for i in resets] == [False, True, True]
    for i in resets:
        assert told.said[i + 1][:3:2] == ("report", told.said[i][2]) and told.said[i + 1][3]  # its report, restarted


def test_the_soak_finds_the_reset_the_bus_rules_find_at_the_same_frame_in_the_same_words():
    frames = traffic(5.0, reset_at=2.0)
    first = next(v for v in feed(rules(), frames) if v.check == "reset")
    monitor = Monitor(WatchConfig(node_id=NODE, host_node=HOST, intervals=INTERVALS), t0=0.0)
    for w in frames:
        monitor.feed(w)
    monitor.close(5.0)
    assert [f.watch for f in monitor.findings] == ["resets"], [f.line() for f in monitor.findings]
    f = monitor.findings[0]
    assert f.t == first.timestamp and first.message.endswith(f.message) and set(f.rules) == set(first.rules)


def _size(obj: Any, seen: set[int]) -> int:
    """How many items the containers reachable from ``obj`` hold (the reader's state, whatever its shape)."""
    if id(obj) in seen or isinstance(obj, (str, bytes, bytearray, int, float, bool, type(None), type)):
        return 0
    seen.add(id(obj))
    n = 0
    if isinstance(obj, dict):
        n += len(obj) + sum(_size(k, seen) + _size(v, seen) for k, v in obj.items())
    elif isinstance(obj, (list, tuple, set, frozenset)) or type(obj).__name__ == "deque":
        n += len(obj) + sum(_size(v, seen) for v in obj)
    attrs = getattr(obj, "__dict__", {})
    slots = [s for c in type(obj).__mro__ for s in getattr(c, "__slots__", ())]
    for v in list(attrs.values()) + [getattr(obj, s, None) for s in slots]:
        n += _size(v, seen)
    return n


def test_the_readers_state_is_the_same_size_after_a_run_three_times_as_long():
    """Memory flat over hours: 200 s and 600 s of a soak's bus leave the reader holding as many items, once its bounded
    keepers are full (the first 100 pairing decisions kept whole, the last 32 requests of each kind)."""
    sizes = []
    for seconds in (200.0, 600.0):
        r = rules()
        assert not feed(r, traffic(seconds))
        sizes.append(_size(r, set()))
    assert sizes[0] == sizes[1], sizes
