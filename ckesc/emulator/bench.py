"""A bench: several emulated ESCs on one power supply, sharing one bus.

Both lanes drive a :class:`Bench`: it delivers a frame to every powered ESC listening at the
frame's bit rate, collects what the ESCs have due, and keeps their flash. Still sans-IO except for
the flash file, which it writes only when told to (:meth:`persist`).
"""

from __future__ import annotations

from typing import Any, Iterable, Mapping

from ..protocol.frame import WireFrame
from . import faults as _faults
from .flash import FlashStore
from .model import EscConfig, EscModel

FaultSpec = Iterable[str] | Mapping[int, Iterable[str]] | None


class Bench:
    def __init__(
        self,
        nodes: Iterable[int] = (1,),
        *,
        faults: FaultSpec = None,
        flash: FlashStore | str | None = None,
        seed: int = 0,
        config: Mapping[str, Any] | None = None,
    ) -> None:
        """``nodes``: the node ids of factory-fresh ESCs, one per slot (ignored for slots whose flash
        already holds a node id). ``faults``: names for every ESC, or ``{slot_node_id: names}``.
        ``config``: extra :class:`EscConfig` fields for every ESC (e.g. ``boot_time``)."""
        self.flash = FlashStore(flash) if isinstance(flash, (str, bytes)) or hasattr(flash, "__fspath__") else flash
        stored = self.flash.load() if self.flash is not None else {}
        node_list = list(nodes)
        if not node_list:
            raise ValueError("a bench needs at least one ESC")
        self.escs: list[EscModel] = []
        for slot, node in enumerate(node_list):
            names = _faults.check(faults.get(node, ()) if isinstance(faults, Mapping) else (faults or ()))
            cfg = EscConfig(slot=slot, node_id=node, seed=seed, faults=names, **dict(config or {}))
            self.escs.append(EscModel(cfg, stored.get(slot)))
        self.powered = False

    # power ------------------------------------------------------------------------------------
    def power_on(self, now: float) -> None:
        self.powered = True
        for esc in self.escs:
            esc.power_on(now)

    def power_off(self, now: float) -> None:
        self.powered = False
        for esc in self.escs:
            esc.power_off(now)
        self.persist()

    # faults -----------------------------------------------------------------------------------
    def set_fault(self, name: str, on: bool = True, node: int | None = None) -> None:
        _faults.check([name])
        for esc in self.escs:
            if node is None or esc.node_id == node:
                (esc.faults.add if on else esc.faults.discard)(name)

    # frames -----------------------------------------------------------------------------------
    def deliver(self, frame: Any, now: float, bitrate: int, sender: EscModel | None = None) -> None:
        for esc in self.escs:
            if esc is not sender and esc.powered and esc.bitrate == bitrate:
                esc.receive(frame, now)

    def next_deadline(self) -> float | None:
        times = [t for t in (esc.next_deadline() for esc in self.escs) if t is not None]
        return min(times) if times else None

    def poll(self, now: float) -> list[tuple[EscModel, WireFrame]]:
        out = [(esc, w) for esc in self.escs for w in esc.poll(now)]
        out.sort(key=lambda pair: pair[1].timestamp)
        return out

    def esc(self, node_id: int) -> EscModel:
        for esc in self.escs:
            if esc.node_id == node_id:
                return esc
        raise KeyError(f"no ESC with node id {node_id} on this bench (have {[e.node_id for e in self.escs]})")

    # flash ------------------------------------------------------------------------------------
    @property
    def dirty(self) -> bool:
        return any(esc.nvm_dirty for esc in self.escs)

    def persist(self) -> None:
        if self.flash is None or not self.dirty:
            return
        self.flash.save({esc.config.slot: esc.nvm for esc in self.escs})
        for esc in self.escs:
            esc.nvm_dirty = False
