"""Rig files: the benches of a test lab, each one a DUT on its own bus with its own power switch
(``fixtures/rigs/*.toml``; ``ckesc run --rig FILE`` runs the suite on all of them at once).

    [rig]            description (optional)
    [bench.<name>]   one bench; <name>: letters, digits, ``_`` and ``-`` (its report directory's name)
      description    free text
      dut            "emulator" | "bus" (default: bus when a [bench.<name>.bus] is given, else emulator)
      lane           --dut emulator: "simulated" (default) | "realtime" (`ckesc emulate` in its own process)
      bus            python-can bus arguments: interface, channel, bitrate, and any other argument of the
                     interface (host, port, fd, ...), each a plain value: --can-interface, --can-channel,
                     --can-bitrate, --can-config KEY=VALUE
      profile        DUT profile: a name (./fixtures/duts, then the shipped ones) or a path (relative to the
                     rig file)
      node_id        the DUT's node id; absent: discovered with GET_ESC_ID
      power          "emulator" | "none" | "manual" | { command = { off = "...", on = "..." } }
                     | { labgrid = { env = "...", target = "..." } }  (env: relative to the rig file)
      place          a labgrid place to acquire before the run (passed on as --labgrid-place)
      bitrate_cmd, host_send_error_ms, allow_motor_spin: as --can-bitrate-cmd, --host-send-error,
                     --allow-motor-spin
      emulator       --dut emulator: { nodes = [1], faults = [...], seed = 0, options = { boot_time = 0.2 }, variants = SEED }
      firmware       the bench's image under test (relative to the rig file), with flash_cmd ("CMD {image}",
                     "builtin" or "labgrid"), flash_timeout (s) and expect_firmware = { firmware_date = "...", ... }:
                     as --firmware, --flash-cmd, --flash-timeout, --expect-firmware (docs/firmware.md)

A rig is checked against this schema (pydantic) when it is loaded, as DUT profiles are: an unknown
section or key, a wrong type or a value out of range is a :class:`RigError` naming the file, the bench
and the key. Each bench becomes the options of one bench's run (:meth:`Bench.options`, the run option table's
dest names, ``ckesc/session/options.py``, whose ``rig`` column names the key that sets each; :meth:`Bench.argv`,
the same as a ``ckesc run`` command line). Sans-IO: only
:func:`load` reads a file.
"""

from __future__ import annotations

import difflib
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from ..bench.profile import validated
from ..bench.sections import Section
from ..protocol.ids import ESC_NODE_IDS
from ..session.options import command_line

BENCH_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_-]{0,63}$")
POWER_WORDS = ("emulator", "none", "manual")


class RigError(ValueError):
    """A rig file that cannot be used: missing, not TOML, or not of the schema (the message names the
    file, the bench and the key)."""


# ----------------------------------------------------------------------------------------- schema
Scalar = str | int | float | bool


class _Bus(BaseModel):
    """python-can's bus arguments: the three every interface has, and any other of the interface's own."""

    model_config = ConfigDict(extra="allow", strict=True)
    interface: str
    channel: str | int | None = None
    bitrate: int | None = Field(None, gt=0)

    @model_validator(mode="after")
    def _plain_values(self) -> _Bus:
        for key, value in (self.model_extra or {}).items():
            if not isinstance(value, Scalar):  # type: ignore[arg-type]
                raise ValueError(f"bus argument {key!r} must be a plain value (string, number, true/false): it is "
                                 "passed as --can-config KEY=VALUE")
        return self


class _Command(Section):
    off: str = Field(min_length=1)
    on: str = Field(min_length=1)


class _Labgrid(Section):
    env: str = Field(min_length=1)
    target: str = Field(min_length=1)


class _PowerTable(Section):
    command: _Command | None = None
    labgrid: _Labgrid | None = None

    @model_validator(mode="after")
    def _exactly_one(self) -> _PowerTable:
        if (self.command is None) == (self.labgrid is None):
            raise ValueError("a power table has exactly one of command = { off, on } or labgrid = { env, target }")
        return self


class _Emulator(Section):
    nodes: list[Annotated[int, Field(ge=ESC_NODE_IDS.start, le=ESC_NODE_IDS.stop - 1)]] = Field([1], min_length=1)
    faults: list[str] = []
    seed: int = 0
    options: dict[str, Scalar] = {}
    variants: int | None = None  # the seed of a drawn conforming combination (ckesc/emulator/variants.py)


class _BenchDoc(Section):
    description: str = ""
    dut: Literal["emulator", "bus"] | None = None
    lane: Literal["simulated", "realtime"] | None = None
    bus: _Bus | None = None
    profile: str | None = None
    node_id: int | None = Field(None, ge=ESC_NODE_IDS.start, le=ESC_NODE_IDS.stop - 1)
    power: str | _PowerTable | None = None
    place: str | None = Field(None, min_length=1)
    bitrate_cmd: str | None = None
    host_send_error_ms: float | None = Field(None, ge=0.0, le=1000.0)
    allow_motor_spin: bool = False
    emulator: _Emulator | None = None
    firmware: str | None = Field(None, min_length=1)
    flash_cmd: str | None = Field(None, min_length=1)
    flash_timeout: float | None = Field(None, gt=0.0)
    expect_firmware: dict[str, Scalar] | None = None

    @field_validator("power", mode="before")
    @classmethod
    def _power(cls, value: Any) -> Any:
        if isinstance(value, str) and value not in POWER_WORDS:
            raise ValueError(f"power {value!r}: one of {', '.join(map(repr, POWER_WORDS))}, or a table "
                             "{ command = { off = ..., on = ... } } or { labgrid = { env = ..., target = ... } }")
        return value

    @model_validator(mode="after")
    def _consistent(self) -> _BenchDoc:
        dut = self.dut or ("bus" if self.bus is not None else "emulator")
        if dut == "bus":
            if self.bus is None:
                raise ValueError("dut = 'bus' needs a bus = { interface = ..., channel = ... }")
            if self.lane is not None or self.emulator is not None:
                raise ValueError("lane and emulator are for dut = 'emulator' (the bench's own emulator)")
            if self.power == "emulator":
                raise ValueError("power 'emulator' is the emulator's own switch: for dut = 'bus' give command, manual, "
                                 "none or labgrid (a `ckesc emulate` reached over socketcand: power = { command = { off = "
                                 "\"ckesc control --port P power off\", on = \"... power on\" } })")
        else:
            if self.bus is not None:
                raise ValueError("a bus is for dut = 'bus'; dut = 'emulator' builds its own")
            if self.power not in (None, "emulator"):
                raise ValueError("dut = 'emulator' switches its emulator's power itself: leave power out or give 'emulator'")
            if self.place is not None or self.bitrate_cmd is not None:
                raise ValueError("place and bitrate_cmd are for dut = 'bus'")
        if self.place is not None and not (isinstance(self.power, _PowerTable) and self.power.labgrid is not None):
            raise ValueError("place (a labgrid place) needs power = { labgrid = { env = ..., target = ... } }")
        return self


class _RigHead(Section):
    description: str = ""


class _RigDoc(Section):
    rig: _RigHead = _RigHead()
    bench: dict[str, _BenchDoc] = Field(min_length=1)

    @field_validator("bench", mode="before")
    @classmethod
    def _names(cls, value: Any) -> Any:
        if isinstance(value, dict):
            for name in value:
                if not BENCH_NAME.match(name):
                    raise ValueError(f"bench name {name!r}: letters, digits, '_' and '-' (it names the bench's report "
                                     "directory), starting with a letter or digit")
        return value


_KNOWN = {(): list(_RigDoc.model_fields), ("rig",): list(_RigHead.model_fields), ("bench", "*"): list(_BenchDoc.model_fields),
          ("bench", "*", "power"): list(_PowerTable.model_fields), ("bench", "*", "power", "command"): list(_Command.model_fields),
          ("bench", "*", "power", "labgrid"): list(_Labgrid.model_fields),
          ("bench", "*", "emulator"): list(_Emulator.model_fields)}


def _clean(loc: tuple) -> list[str]:
    """An error's location without pydantic's union and validator tags (``power._PowerTable.command``)."""
    return [str(p) for p in loc if not (str(p).startswith("_") or str(p).startswith("function-") or p == "str")]


def _errors(path: Path, errors: list[dict[str, Any]]) -> list[str]:
    """pydantic's errors as lines; of a union (power: a word or a table) only the branch given is told, and
    a key "missing" beside an unknown one (a misspelling) is left to the unknown key's line."""
    tables = {tuple(_clean(e["loc"])) for e in errors if any("_PowerTable" in str(p) for p in e["loc"])}
    unknown_in = {tuple(_clean(e["loc"]))[:-1] for e in errors if e["type"] == "extra_forbidden"}
    out = []
    for e in errors:
        loc = tuple(_clean(e["loc"]))
        if "str" in e["loc"] and any(t[:len(loc)] == loc for t in tables):
            continue
        if e["type"] == "missing" and loc[:-1] in unknown_in:
            continue
        out.append(_describe(path, list(loc), e))
    return list(dict.fromkeys(out))


def _describe(path: Path, loc: list[str], err: dict[str, Any]) -> str:
    in_bench = len(loc) >= 2 and loc[0] == "bench"
    head = f"{path}: " + (f"[bench.{loc[1]}] " if in_bench else "")
    where = ".".join(loc[2:] if in_bench else loc)
    if err["type"] == "extra_forbidden":
        shape = tuple("*" if i == 1 and in_bench else p for i, p in enumerate(loc[:-1]))
        known = _KNOWN.get(shape, [])
        close = difflib.get_close_matches(loc[-1], known, n=1)
        what = "section" if len(loc) == 1 else "key"
        parent = ".".join((loc[2:] if in_bench else loc)[:-1])
        return (f"{head}{parent + ': ' if parent else ''}unknown {what} {loc[-1]!r}" + (f" (known: {', '.join(known)})" if known else "")
                + (f"; did you mean {close[0]!r}?" if close else ""))
    value = err.get("input")
    shown = f" = {value!r}" if not isinstance(value, dict) else ""
    if err["type"] == "value_error":  # our own validators' messages: as written
        return f"{head}{where}{shown}{': ' if where else ''}{err['ctx']['error']}"
    if err["type"] == "missing":
        return f"{head}{where}: missing"
    return f"{head}{where}{shown}: {err['msg'].lower()}"


# ----------------------------------------------------------------------------------------- benches
@dataclass
class Bench:
    """One bench of a rig, as the options of one bench's run."""

    name: str
    description: str = ""
    #: the run options (dest names, ``session/options.py``: its BENCH_OPTIONS) this bench sets; any other keeps its
    #: default
    settings: dict[str, Any] = field(default_factory=dict)

    def options(self) -> dict[str, Any]:
        return dict(self.settings)

    def argv(self) -> list[str]:
        """The same bench as ``ckesc run`` / pytest options (``--dut bus --can-interface ...``)."""
        return command_line(self.settings)

    def command_line(self) -> str:
        return shlex.join(["ckesc", "run", *self.argv()])

    @property
    def power(self) -> str:
        return str(self.settings.get("power") or ("emulator" if self.settings.get("dut") == "emulator" else "none"))


@dataclass
class Rig:
    path: str
    description: str
    benches: dict[str, Bench]

    def select(self, names: list[str] | None) -> list[Bench]:
        """The benches named (in the order given), or all (in the file's order); an unknown name is a
        :class:`RigError`."""
        if not names:
            return list(self.benches.values())
        unknown = [n for n in names if n not in self.benches]
        if unknown:
            close = difflib.get_close_matches(unknown[0], list(self.benches), n=1)
            raise RigError(f"{self.path}: no bench {unknown[0]!r} (benches: {', '.join(self.benches)})"
                           + (f"; did you mean {close[0]!r}?" if close else ""))
        return [self.benches[n] for n in dict.fromkeys(names)]


def _relative(value: str, base: Path) -> str:
    """A path written in the rig file, relative to the rig file's directory (a bare profile name stays one)."""
    p = Path(value).expanduser()
    return str(p if p.is_absolute() else (base / p))


def _bench(name: str, doc: _BenchDoc, base: Path) -> Bench:
    dut = doc.dut or ("bus" if doc.bus is not None else "emulator")
    s: dict[str, Any] = {"dut": dut}
    if dut == "emulator":
        s["lane"] = doc.lane or "simulated"
        emu = doc.emulator or _Emulator()
        s["nodes"] = ",".join(map(str, emu.nodes))
        if emu.faults:
            s["emulator_faults"] = ",".join(emu.faults)
        if emu.seed:
            s["emulator_seed"] = emu.seed
        if emu.options:
            s["emulator_option"] = [f"{k}={v}" for k, v in emu.options.items()]
        if emu.variants is not None:
            s["emulator_variants"] = emu.variants
    else:
        assert doc.bus is not None
        s["can_interface"] = doc.bus.interface
        if doc.bus.channel is not None:
            s["can_channel"] = str(doc.bus.channel)
        if doc.bus.bitrate is not None:
            s["can_bitrate"] = doc.bus.bitrate
        extra = doc.bus.model_extra or {}
        if extra:
            s["can_config"] = [f"{k}={str(v).lower() if isinstance(v, bool) else v}" for k, v in extra.items()]
    if doc.profile:
        s["profile"] = _relative(doc.profile, base) if (Path(doc.profile).suffix or "/" in doc.profile) else doc.profile
    if doc.node_id is not None:
        s["node_id"] = doc.node_id
    power = doc.power
    if isinstance(power, str):
        s["power"] = power
    elif power is not None and power.command is not None:
        s.update(power="command", power_off_cmd=power.command.off, power_on_cmd=power.command.on)
    elif power is not None and power.labgrid is not None:
        s.update(power="labgrid", labgrid_env=_relative(power.labgrid.env, base), labgrid_target=power.labgrid.target)
    if doc.place is not None:
        s["labgrid_place"] = doc.place
    if doc.bitrate_cmd is not None:
        s["can_bitrate_cmd"] = doc.bitrate_cmd
    if doc.host_send_error_ms is not None:
        s["host_send_error"] = doc.host_send_error_ms
    if doc.allow_motor_spin:
        s["allow_motor_spin"] = True
    if doc.firmware is not None:
        s["firmware"] = _relative(doc.firmware, base)
    for key in ("flash_cmd", "flash_timeout"):
        if getattr(doc, key) is not None:
            s[key] = getattr(doc, key)
    if doc.expect_firmware:
        s["expect_firmware"] = ",".join(f"{k}={v}" for k, v in doc.expect_firmware.items())
    return Bench(name=name, description=doc.description, settings=s)


def parse(text: str, path: str | Path = "<rig>") -> Rig:
    """A :class:`Rig` from a rig file's text (``path`` names it in errors, and relative paths in it are
    taken from its directory)."""
    path = Path(path)
    doc = validated(_RigDoc, text, path, RigError, lambda errors: "; ".join(_errors(path, errors)))
    base = path.parent
    return Rig(path=str(path), description=doc.rig.description,
               benches={name: _bench(name, b, base) for name, b in doc.bench.items()})


def load(path: str | Path) -> Rig:
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RigError(f"{path}: no such rig file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise RigError(f"{path}: cannot read the rig file: {exc}") from None
    return parse(text, p)
