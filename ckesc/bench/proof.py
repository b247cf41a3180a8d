"""The bench proven before the DUT is judged (``--dut bus``): who answers GET_ESC_ID on the bus, the node id
given checked against them, and, where the run will cycle power, the power switch itself: off, the DUT falls
silent; on, it reports again within the profile's times. Every failure is a :class:`.errors.PreflightError`
(one line, exit status 2, before any test), naming the bus, the nodes heard or the power command.

What the preflight proves here the tests no longer have to doubt: a power command that fails, hangs or switches
nothing later in the run is the bench's (:class:`.errors.PowerFailed`: ERROR), never the DUT's FAIL.
"""

from __future__ import annotations

from .errors import PowerFailed, PreflightError
from .lanes import BusLane
from .link import DutUnreachable, Link, echo_probe
from .profile import DutProfile
from .supply import Supply


def _nodes(ids: list[int]) -> str:
    return ", ".join(f"node {n}" for n in ids) if ids else "no node"


def discover(lane: BusLane, profile: DutProfile, node_id: int | None, where: str) -> Link:
    """A :class:`.link.Link` to the DUT on ``lane``: GET_ESC_ID asked until the profile's boot time (and a second) has
    passed, ``node_id`` (if given) among the nodes that answered."""
    lane.find_echo(echo_probe(nibble_order=profile.nibble_order))
    link = Link(lane, profile, node_id=node_id if node_id is not None else 0)
    try:
        first = link.discover()
    except DutUnreachable:
        raise PreflightError(f"no ESC answered GET_ESC_ID on the bus ({where}) within {profile.boot_s + 1.0:g} s (the "
                             f"profile's boot_s and a second): is it powered, wired, at {lane.bitrate} bit/s (--can-bitrate, "
                             "or the adapter's own setting), and not at node id 0x7D (which answers nothing)?") from None
    heard = list(getattr(link, "discovered", [first]))
    if node_id is not None and node_id not in heard:
        raise PreflightError(f"node {node_id} did not answer GET_ESC_ID; heard: {_nodes(heard)} (give --node-id "
                             f"{heard[0]}, or leave it out to take the first that answers)")
    link.node_id = node_id if node_id is not None else first
    link.nodes = heard
    return link


def prove_power(link: Link, what: dict[str, str]) -> str:
    """Switch the DUT off and on once, as the run will: off, it falls silent (no frame from it in the second half of
    the profile's ``off_s``); on, it reports again (MSG1..MSG3) within the profile's ``boot_s`` and one longest report
    interval. ``what``: how the switch's off and on are named (the commands). Returns what was seen."""
    lane, profile, node = link.lane, link.profile, link.node_id
    supply = Supply(link)
    t = link.now()
    if not supply.await_reports(t, t + supply.ready_bound_s(0.0)):
        return "not proven: the DUT was not reporting before the power was switched"
    off_s = profile.off_s
    try:
        lane.power.off()
    except PowerFailed as exc:
        raise PreflightError(f"power off: {exc}") from None
    t_off = link.now()
    try:
        link.wait(off_s)
    except BaseException:  # Ctrl-C while the DUT is off: it is switched on again on the way out
        _on_anyway(lane)
        raise
    late = [f.timestamp for f in link.frames(since=t_off + off_s / 2, source=node)]
    late += [g.msg.timestamp for g in link.undecoded(since=t_off + off_s / 2, source=node)]
    if late:
        raise PreflightError(f"the power switch switched nothing: node {node} kept sending after {what['off']} "
                             f"({len(late)} frame(s) {off_s / 2:g}..{off_s:g} s after it, the profile's off_s {off_s:g} s): "
                             "does the command switch the DUT's supply?")
    try:
        lane.power.on()
    except PowerFailed as exc:
        raise PreflightError(f"power on: {exc}") from None
    on = link.now()
    bound = supply.ready_bound_s()
    heard = supply.await_reports(on, on + bound)
    if not heard:
        raise PreflightError(f"node {node} did not report again within {bound:.2f} s after {what['on']} (the profile's "
                             f"boot_s {profile.boot_s:g} s and one longest report interval): does the command switch the "
                             "DUT's supply on, or does it boot slower than boot_s says?")
    first = min(heard.values())
    return f"proven: silent when off, first report {(first - on) * 1000:.0f} ms after power-on"


def _on_anyway(lane: BusLane) -> None:
    try:
        lane.power.on()
    except Exception:  # noqa: BLE001 - best effort on an exit path
        pass
