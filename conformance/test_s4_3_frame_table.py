"""Spec section 4.3: List of data frame types - the vendor id ranges (4.3.1) and the priority of every
frame type in the data frame type table (4.3.2, F5).

Judged, like section 4.1's framing, on every frame the DUT sends: the traffic provoked here (every
kind of frame a DUT sends, plus the one request a DroneCAN flight controller sends every node it
sees: GetNodeInfo, outside the vendor range) and, in the tests marked ``last``, the whole run's.
The wire helpers it shares with section 4.1 are in ``conformance/wire.py``.
"""

from __future__ import annotations

import pytest

from ckesc.protocol import catalogue as cat
from ckesc.protocol.ids import MESSAGE_VENDOR_RANGE, SERVICE_VENDOR_RANGE, Kind, Priority, priority_name

from . import wire
from .wire import SCOPES, HeardFrame, check_each, describe, in_scope

SECTION = "4.3"
traffic = wire.traffic  # fixture: the provoked traffic, once per module

#: The answers the table gives no priority (240, 241, 242: F5-unlisted)
UNLISTED = tuple(s for s in cat.CATALOGUE if s.service and s.responses and s.priority is None)


def _range_text(r: range) -> str:
    return f"[{r.start}, {r.stop})"


def message_range_problems(h: HeardFrame) -> list[str]:
    cid = h.cid
    if h.extended and cid.kind is Kind.MESSAGE and cid.type_id not in MESSAGE_VENDOR_RANGE:
        return [f"message type id {cid.type_id} outside the vendor range {_range_text(MESSAGE_VENDOR_RANGE)}"]
    return []


def service_range_problems(h: HeardFrame) -> list[str]:
    cid = h.cid
    if h.extended and cid.kind is not Kind.MESSAGE and cid.type_id not in SERVICE_VENDOR_RANGE:
        return [f"service id {cid.type_id} outside the vendor range {_range_text(SERVICE_VENDOR_RANGE)}"]
    return []


def priority_problems(h: HeardFrame) -> list[str]:
    """F5: the table's priority for every frame type that lists one."""
    spec = h.spec
    if not h.extended or spec is None or spec.priority is None:
        return []
    got = h.cid.priority
    if got != spec.priority:
        return [f"{spec.title} at priority {got} ({priority_name(got)}), the table says {spec.priority.name} ({int(spec.priority)})"]
    return []


def _not_in_table(frames: list[HeardFrame]) -> list[str]:
    return sorted({f"{h.cid.kind.label} {h.cid.type_id}" for h in frames if h.extended and h.spec is None})


@pytest.mark.requirement("4.3.1-1")
@pytest.mark.parametrize("scope", SCOPES)
def test_message_type_ids_in_the_vendor_range(traffic, ckesc_run, scope):
    """Every message frame the DUT sends has a type id in [20000, 21000)."""
    frames = in_scope(scope, traffic, ckesc_run)
    problems = check_each(frames, message_range_problems)
    assert not problems, describe(problems)


@pytest.mark.requirement("4.3.1-2")
@pytest.mark.parametrize("scope", SCOPES)
def test_service_ids_in_the_vendor_range(traffic, ckesc_run, scope):
    """Every service frame the DUT sends has a service id in [200, 256): it does not answer a request
    outside the range either (the provoked traffic includes DroneCAN's GetNodeInfo)."""
    frames = in_scope(scope, traffic, ckesc_run)
    problems = check_each(frames, service_range_problems)
    assert not problems, describe(problems)


@pytest.mark.requirement("4.3.2-T", "F5")
@pytest.mark.parametrize("scope", SCOPES)
def test_every_frame_type_at_the_table_priority(traffic, ckesc_run, scope):
    """Every frame the DUT sends whose type the table gives a priority carries that priority
    (HIGHEST 0, HIGH 8, MEDIUM 16, LOW 24, LOWEST 31): reports LOWEST, MSG Control and GET_ESC_ID
    answers MEDIUM, each service answer its service's."""
    frames = in_scope(scope, traffic, ckesc_run)
    problems = check_each(frames, priority_problems)
    assert not problems, f"[F5] {describe(problems)}"
    assert any(h.spec is not None and h.spec.priority is not None for h in traffic.heard), "no frame with a listed priority"


@pytest.mark.requirement("F5-unlisted")
def test_observe_priority_of_answers_the_table_lists_none(traffic, dut):
    """240, 241 and 242 have no priority in the table: the priority of the answer to a request sent at
    each of the table's five priorities is recorded (does the DUT mirror the request's?); so are the
    frame types outside the table that the DUT sent in the provoked traffic."""
    for spec in UNLISTED:
        fields = {"option": min(spec.request.field("option").codes or {0: ""})}  # type: ignore[union-attr]
        seen = {}
        for p in Priority:
            ex = dut.request(spec.name, fields, priority=int(p))
            seen[p.name] = "no answer" if ex.response is None else priority_name(ex.response.priority)
        dut.record.observe(f"{spec.title} ({spec.type_id}) answer priority, by request priority", seen)
    dut.record.observe("frame types the table does not list", _not_in_table(traffic.heard) or "none")
