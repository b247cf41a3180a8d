"""The emulated bench: several emulated ESCs on one power supply, sharing one bus (the host's side of a
bench, its lanes and power, is :mod:`ckesc.bench`).

Both lanes drive an :class:`EmulatedBench`: it delivers a frame to every powered ESC listening at the
frame's bit rate, collects what the ESCs have due, and keeps their flash. Still sans-IO except for
the flash file, which it writes only when told to (:meth:`persist`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Iterable, Mapping

from ..protocol.errors import DecodeError
from ..protocol.frame import Decoder, Frame, WireFrame, classify
from . import faults as _faults
from .flash import FlashStore
from .model import HANDLED, THROTTLE_FRAMES, EscConfig, EscModel

FaultSpec = Iterable[str] | Mapping[int, Iterable[str]] | None
INF = float("inf")
#: throttle frames kept decoded, and ids kept classified (a host sending ever new ones must not grow the memory)
_THROTTLE_DECODED_MAX = 1024
#: the throttle index's entry for the ESCs every throttle frame reaches (a fault that reads any channel)
_ANY = ("*", None)


def _stamp(pair: tuple[EscModel, WireFrame]) -> float:
    return pair[1].timestamp


def _or_inf(t: float | None) -> float:
    return INF if t is None else t


class EmulatedBench:
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
        node_list = list(nodes)  # none: a bench with no ESC (``ckesc emulate --nodes none``, a bare hub)
        self.escs: list[EscModel] = []
        for slot, node in enumerate(node_list):
            names = frozenset(faults.get(node, ()) if isinstance(faults, Mapping) else (faults or ()))
            cfg = EscConfig(slot=slot, node_id=node, seed=seed, faults=names, **dict(config or {}))  # checks them
            self.escs.append(EscModel(cfg, stored.get(slot)))
        self.powered = False
        self._decoder = Decoder(track_requests=False)
        # each ESC's next deadline, refreshed only for the ESCs a call touched (the hot path of both lanes)
        self._deadlines: list[float] = [INF] * len(self.escs)  # INF: nothing scheduled
        self._throttle_index: dict[tuple[str, int | None], list[EscModel]] | None = None
        self.ignored = 0  # frames on the bus that no ESC acts on (other ESCs' reports and answers)
        #: throttle frames decoded, by (id, bytes), with their :meth:`_throttle_targets` key: a stream
        #: repeats the same few (its transfer ids cycle through 32), hours long; a throttle frame's decoding depends on
        #: nothing else and no ESC keeps or changes it
        self._throttle_decoded: dict[tuple[int, bytes], tuple[Frame, tuple[str, int | None]]] = {}
        #: each extended id's (kind, catalogue name or None), as classify gives them (every frame on the bus asks)
        self._classified: dict[int, tuple[Any, str | None]] = {}

    def touch(self, esc: EscModel | None = None) -> None:
        """Refresh cached deadlines after changing an ESC from outside (``None``: all of them)."""
        self._throttle_index = None
        for i, e in enumerate(self.escs):
            if esc is None or e is esc:
                self._deadlines[i] = _or_inf(e.next_deadline())

    # power ------------------------------------------------------------------------------------
    def power_on(self, now: float) -> None:
        self.powered = True
        for esc in self.escs:
            esc.power_on(now)
        self.touch()

    def power_off(self, now: float) -> None:
        self.powered = False
        for esc in self.escs:
            esc.power_off(now)
        self.touch()
        self.persist()

    # faults -----------------------------------------------------------------------------------
    def set_fault(self, name: str, on: bool = True, node: int | None = None) -> None:
        """Switch fault ``name`` (``NAME=SECONDS``: a soak fault with its onset moved) on or off."""
        [name] = _faults.check([entry := name])
        onsets = _faults.onsets_in([entry])
        if node is not None:
            self.esc(node)  # raises KeyError naming the node ids on the bench
        for esc in self.escs:
            if node is None or esc.node_id == node:
                (esc.faults.add if on else esc.faults.discard)(name)
                if on and onsets:
                    esc.config.onsets = {**esc.config.onsets, **onsets}
                    esc.onsets_moved()  # counted from the ESC's last power-up
        self.touch()

    def set_self_test_fault(self, code: int, node: int | None = None) -> None:
        """What the power-up self-test of one ESC or all will find from the next power-up on (fault
        code 1, 0: passed): a bench that can make the self-test fail, e.g. a phase left open."""
        for esc in self.escs:
            if node is None or esc.node_id == node:
                esc.config = dataclasses.replace(esc.config, self_test_fault=code)
        self.touch()

    def set_pwm_input(self, value: int | None, node: int | None = None) -> None:
        """The analog throttle input (0..2000; None: no signal) of one ESC or all."""
        for esc in self.escs:
            if node is None or esc.node_id == node:
                esc.pwm_input = value
        self.touch()

    # frames -----------------------------------------------------------------------------------
    def deliver(self, frame: Any, now: float, bitrate: int, sender: EscModel | None = None) -> None:
        """A frame on the bus reaches every powered ESC that listens at its bit rate (decoded once for all).

        Frames no ESC acts on (other ESCs' reports) are only counted, and a throttle frame goes only
        to the ESCs it can address (:meth:`EscModel.throttle_keys`): the hot path of a busy bus."""
        plain = isinstance(frame, WireFrame)  # a data frame (the simulated lane's; remote and error frames come as Messages)
        key = (frame.arbitration_id, frame.data) if plain and frame.is_extended_id else None
        # a throttle frame heard before (a stream's: hours of them) is known by its id and bytes alone: its decoding
        # and the key of the ESCs it can address
        known_throttle = self._throttle_decoded.get(key) if key is not None else None
        if known_throttle is not None:
            decoded, targets_key = known_throttle
            index = self._throttle_index  # (_throttle_targets', without its call)
            for esc in self._throttle_targets(targets_key) if index is None else index.get(targets_key) or index[_ANY]:
                # (never self.escs: the index keeps its own lists)
                if esc is not sender and esc.powered and esc.state.bitrate == bitrate:
                    if esc.receive(frame, now, decoded=decoded):
                        self._deadlines[0 if len(self.escs) == 1 else self.escs.index(esc)] = _or_inf(esc.next_deadline())
            return
        decoded: Frame | DecodeError
        if (frame.is_extended_id if plain else getattr(frame, "is_extended_id", True)):
            can_id = frame.arbitration_id
            known = self._classified.get(can_id)
            if known is None:
                if len(self._classified) >= _THROTTLE_DECODED_MAX:
                    self._classified.clear()
                kind, _, _, _, spec = classify(can_id)
                known = self._classified[can_id] = (kind, spec.name if spec is not None else None)
            kind, name = known
            if name is not None and (kind, name) not in HANDLED:
                self.ignored += 1  # other ESCs' reports and answers: nobody acts on them, no need to decode
                return
            if name is None or name not in THROTTLE_FRAMES:
                key = None  # (only throttle frames are kept decoded)
        try:
            decoded = self._decoder.decode(frame)
        except DecodeError as exc:
            decoded = exc
        targets = self.escs
        if isinstance(decoded, Frame) and decoded.spec is not None:
            name = decoded.spec.name
            if name in THROTTLE_FRAMES:
                targets_key = (name, decoded.fields["group"] if name == "raw_command_12b" else None)
                targets = self._throttle_targets(targets_key)
                if key is not None:
                    if len(self._throttle_decoded) >= _THROTTLE_DECODED_MAX:
                        self._throttle_decoded.clear()
                    self._throttle_decoded[key] = (decoded, targets_key)
        changed = False
        for esc in targets:
            if esc is not sender and esc.powered and esc.listens_at(bitrate):
                if esc.receive(frame, now, decoded=decoded):
                    self._deadlines[0 if len(self.escs) == 1 else self.escs.index(esc)] = _or_inf(esc.next_deadline())
                    changed = True
        if changed and targets is self.escs:
            self._throttle_index = None  # a service may have changed a node's throttle channel

    def _throttle_targets(self, wanted: tuple[str, int | None]) -> list[EscModel]:
        """The ESCs a throttle frame can address, by (its name, its RawCommand_12b group or None)."""
        if self._throttle_index is None:
            index: dict[tuple[str, int | None], list[EscModel]] = {}
            everything: list[EscModel] = []
            for esc in self.escs:
                keys = esc.throttle_keys()
                if keys is None:
                    everything.append(esc)
                else:
                    for key in keys:
                        index.setdefault(key, []).append(esc)
            self._throttle_index = {k: sorted(set(v) | set(everything), key=self.escs.index) for k, v in index.items()}
            self._throttle_index[_ANY] = everything
        return self._throttle_index.get(wanted) or self._throttle_index[_ANY]

    def next_deadline(self) -> float | None:
        t = min(self._deadlines)
        return None if t == INF else t

    def poll(self, now: float) -> list[tuple[EscModel, WireFrame]]:
        """What the ESCs due by ``now`` send, in due order."""
        out: list[tuple[EscModel, WireFrame]] = []
        for i, t in enumerate(self._deadlines):
            if t <= now:
                esc = self.escs[i]
                out += [(esc, w) for w in esc.poll(now)]
                t = esc.next_deadline()
                self._deadlines[i] = INF if t is None else t
        if len(out) > 1:
            out.sort(key=_stamp)
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
