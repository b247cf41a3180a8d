"""DUT profiles: what a device has, how precisely the lane can time it, and which READINGs it
overrides. The profiles this package ships (``ckesc/bench/profiles/*.toml``: ``emulator``,
``ckesc-generic``, ``vcan-vm``) are package data, found by name from any directory; a profile of
your own is a path, or a name found in ``./fixtures/duts/``.

    [dut]          name, description
    [capabilities] led, motor, pwm_input, motor_temperature, multi_node   (true/false)
    [timing]       error_s: the bench's measurement error (host + adapter timestamps); margins below it
                   are INCONCLUSIVE
                   jitter_s: the DUT's report-interval jitter allowance (R9): widens what a single report
                   interval may do (the live bus rules, R9a's first reports) and a mean's two ends, over its gaps
                   boot_s: power-on to first report; off_s: off time of a power cycle
                   stamp: "end" | "start": which end of a frame the bench's timestamps mark
    [readings]     R4 = "lsb" | "swapped"   (12-bit nibble order)
    [functions]    absent = ["get_rec", ...]: optional functions the ESC lacks (R9b; the names are
                   ckesc.protocol.functions.OPTIONAL): their tests are SKIPPED as "not claimed"

A profile is checked against this schema (pydantic) when it is loaded: an unknown section or key, a
wrong type or a value out of range is a :class:`ProfileError` naming the file, the key and, for an
unknown key, the known ones with the closest match.
"""

from __future__ import annotations

import difflib
import tomllib
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from importlib import resources
from pathlib import Path
from typing import Any, Literal, TypeVar

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_validator

from ..protocol.functions import CORE, OPTIONAL
from .sections import Section

M = TypeVar("M", bound=BaseModel)

CAPABILITIES = ("led", "motor", "pwm_input", "motor_temperature", "multi_node")

#: the profiles shipped inside the package (package data: there in a wheel as in a checkout)
SHIPPED = resources.files(__package__).joinpath("profiles")


def profile_dirs() -> tuple[Any, ...]:
    """Where profile names are looked up: the current directory's ``fixtures/duts`` (a bench's own
    profiles), then the shipped ones."""
    return (Path.cwd() / "fixtures" / "duts", SHIPPED)


class ProfileError(ValueError):
    """A DUT profile that cannot be used: missing, not TOML, or not of the schema. The message names
    the file (and the key)."""


# ----------------------------------------------------------------------------------------- schema
class _Dut(Section):
    name: str | None = Field(None, description="how the reports name the DUT (default: the file's name)")
    description: str = Field("", description="free text, shown in the reports")


class _Capabilities(Section):
    led: bool = Field(False, description="an LED Set LED (4.4.20) can drive")
    motor: bool = Field(False, description="a motor attached (spinning it still needs --allow-motor-spin)")
    pwm_input: bool = Field(False, description="a PWM throttle input the bench can drive (Throttle Select, 4.4.23)")
    motor_temperature: bool = Field(False, description="a motor temperature sensor")
    multi_node: bool = Field(False, description="several ESCs on the bus (the multi-ESC tests)")


#: A real bench's timing error, written here once (issue #28) and imported by everything that takes it: 2 ms, a
#: full-speed USB adapter's 1 ms poll each way (receive stamps, and a frame sent reaching the bus) plus the host's
#: scheduling, as the shipped ``ckesc-generic`` profile states it. It is
#:
#: * the bench's error on a real bus (``--dut bus``) whose profile states none (:meth:`DutProfile.on_a_real_bus`;
#:   the run prints it when it is taken: a bench is never assumed exact),
#: * the real-time emulator lane's least stated error (``ckesc emulate``, its socketcand hub and the suite share one
#:   machine's scheduler: ``station.py``, ``realtime_lane.py``),
#: * how much later than the host clock at ``send()`` a frame may reach the bus where the adapter does not echo the
#:   host's frames (``--host-send-error``'s default, :attr:`ckesc.bench.lanes.Lane.host_send_error`).
#:
#: A bench that knows better states its own (the profile's ``[timing] error_s``, ``--host-send-error``); a use that
#: needs another figure gets its own named constant, with its reason, not a second ``0.002``
#: (``tests/protocol/test_no_tolerance_literals.py`` fails on one)
DEFAULT_BUS_ERROR_S = 0.002
#: Which end of a frame the bench's timestamps mark when the profile does not say: its end, as SocketCAN stamps a
#: frame when it has been received (and the echo of the host's own frame when it has been sent), socketcand passes
#: those stamps on, and the emulators stamp. Some adapters stamp the start of frame (their hardware's SOF stamp)
DEFAULT_STAMP = "end"
STAMPS = ("end", "start")


class _Timing(Section):
    model_config = ConfigDict(extra="forbid", strict=False)  # an int (2) is a float here, a string is not
    error_s: float = Field(0.0, ge=0.0, le=10.0, description=(
        "**the bench's** measurement error (host + adapter timestamps): a timing margin smaller than it is INCONCLUSIVE"))
    jitter_s: float = Field(0.0, ge=0.0, le=1.0, description=(
        "**the DUT's** report-interval jitter allowance: how far one single report interval (R9) may stray beyond the "
        "suite's own allowance (the live bus rules; a first report after a restart, R9a, too); a mean interval a test "
        "judges only at its two ends, over its number of gaps, and a test whose purpose is R9 reads enough gaps to keep "
        "that near 1 ms (R9: an ESC that reports every 25 ms instead of 20 FAILs however much jitter it declares). It "
        "widens what the DUT may do; error_s still decides INCONCLUSIVE around it. The reports state both"))
    boot_s: float = Field(1.0, ge=0.0, le=600.0, description="power-on to first report")
    off_s: float = Field(1.0, ge=0.0, le=600.0, description="off time of a power cycle")
    stamp: Literal["end", "start"] = Field(DEFAULT_STAMP, description=(
        "which end of a frame **the bench's** timestamps mark: \"end\" (SocketCAN, socketcand, the emulators) or "
        "\"start\" (an adapter stamping the start of frame); the suite converts a stamp to a frame's start and end "
        "with it. Left out on a real bus, the run prints the default it takes"))


class _Readings(Section):
    R4: Literal["lsb", "swapped"] = Field("lsb", description="RawCommand_12b's 12-bit nibble order (R4)")


class _Functions(Section):
    absent: list[str] = Field([], description=(
        "optional functions the ESC lacks (R9b): their tests are SKIPPED as \"not claimed\""))

    @field_validator("absent")
    @classmethod
    def _optional_only(cls, names: list[str]) -> list[str]:
        for name in names:
            if name in CORE:
                raise ValueError(f"{name!r} ({CORE[name]}) cannot be declared absent: R9b keeps 4.1, 4.3, GET_ESC_ID, "
                                 "MSG Control, MSG1..3, RawCommand (all three formats), Set ID, Set Baud, Set/Get Freq "
                                 "and ESC Information in every conformance claim")
            if name not in OPTIONAL:
                close = difflib.get_close_matches(name, list(OPTIONAL), n=1)
                raise ValueError(f"unknown function {name!r} (optional functions: {', '.join(OPTIONAL)})"
                                 + (f"; did you mean {close[0]!r}?" if close else ""))
        return list(dict.fromkeys(names))


class _ProfileDoc(Section):
    dut: _Dut = _Dut()
    capabilities: _Capabilities = _Capabilities()
    timing: _Timing = _Timing()
    readings: _Readings = _Readings()
    functions: _Functions = _Functions()


#: the profile's schema (sections and keys, with types, defaults, ranges and descriptions): the documentation's
#: key table is made from it
PROFILE_SCHEMA: type[BaseModel] = _ProfileDoc


def _model_at(loc: tuple) -> type[BaseModel] | None:
    model: Any = _ProfileDoc
    for part in loc:
        sub = model.model_fields.get(part) if isinstance(part, str) else None
        if sub is None or not (isinstance(sub.annotation, type) and issubclass(sub.annotation, BaseModel)):
            return model if part == loc[-1] else None
        model = sub.annotation
    return model


def _describe(path: Path, err: dict[str, Any]) -> str:
    loc = tuple(err["loc"])
    where = ".".join(str(p) for p in loc)
    if err["type"] == "extra_forbidden":
        parent = _model_at(loc) or _ProfileDoc
        known = list(parent.model_fields)
        close = difflib.get_close_matches(str(loc[-1]), known, n=1)
        what = "section" if len(loc) == 1 else "key"
        hint = f"; did you mean {close[0]!r}?" if close else ""
        prefix = f"[{'.'.join(map(str, loc[:-1]))}] " if len(loc) > 1 else ""
        return f"{path}: {prefix}unknown {what} {str(loc[-1])!r} (known: {', '.join(known)}){hint}"
    value = err.get("input")
    if err["type"] == "value_error":  # our own validators' messages: as written
        return f"{path}: {where} = {value!r}: {err['ctx']['error']}"
    return f"{path}: {where} = {value!r}: {err['msg'].lower()}"


def validated(model: type[M], text: str, path: Path, error: type[Exception], describe: Callable[[list], str]) -> M:
    """A TOML document of ``model``'s schema (a DUT profile, a rig file); ``error`` says what is wrong: not TOML,
    or ``describe(pydantic's errors)``."""
    try:
        raw: dict[str, Any] = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML: {exc}") from None
    try:
        return model.model_validate(raw)
    except ValidationError as exc:
        raise error(describe(exc.errors())) from None


# ----------------------------------------------------------------------------------------- profile
@dataclass
class DutProfile:
    name: str = "unnamed"
    description: str = ""
    capabilities: dict[str, bool] = field(default_factory=dict)
    error_s: float = 0.0
    jitter_s: float = 0.0
    boot_s: float = 1.0
    off_s: float = 1.0
    readings: dict[str, str] = field(default_factory=dict)
    path: str | None = None
    #: optional functions the DUT lacks (R9b): not part of its conformance claim
    absent: tuple[str, ...] = ()
    #: which end of a frame the bench's timestamps mark ("end" or "start")
    stamp: str = DEFAULT_STAMP
    #: the [timing] keys the profile states (the others are defaults: :meth:`on_a_real_bus` names those it takes)
    stated: frozenset[str] = frozenset({"error_s", "stamp"})
    #: one line for each limit a real bus needs that the profile left out, and the default taken (:meth:`on_a_real_bus`)
    defaults_taken: tuple[str, ...] = ()

    def on_a_real_bus(self) -> DutProfile:
        """This profile as a real bus (``--dut bus``) uses it: the limits a real bus cannot do without (the bench's
        timing error, which end of a frame its stamps mark) as stated, or the named defaults
        (:data:`DEFAULT_BUS_ERROR_S`, :data:`DEFAULT_STAMP`), each default taken said in :attr:`defaults_taken`
        (the run prints them and the reports keep them)."""
        notes: list[str] = []
        profile = self
        if "error_s" not in self.stated:
            profile = replace(profile, error_s=DEFAULT_BUS_ERROR_S)
            notes.append(f"the profile {self.name!r} states no [timing] error_s: the bench's error is taken as "
                         f"{DEFAULT_BUS_ERROR_S * 1000:g} ms (DEFAULT_BUS_ERROR_S, the default for a real bus)")
        if "stamp" not in self.stated:
            notes.append(f"the profile {self.name!r} states no [timing] stamp: frame timestamps are taken as marking the "
                         f"frame's {DEFAULT_STAMP} (DEFAULT_STAMP, SocketCAN's; say stamp = \"start\" for an adapter that stamps the start "
                         "of frame)")
        return replace(profile, defaults_taken=tuple(notes))

    def claims(self, function: str) -> bool:
        """Whether the conformance claim includes ``function`` (a core function always)."""
        if function not in OPTIONAL and function not in CORE:
            raise KeyError(f"unknown function {function!r}; optional: {', '.join(OPTIONAL)}")
        return function not in self.absent

    def has(self, capability: str) -> bool:
        if capability not in CAPABILITIES:
            raise KeyError(f"unknown capability {capability!r}; known: {', '.join(CAPABILITIES)}")
        return bool(self.capabilities.get(capability, False))

    @property
    def nibble_order(self) -> str:
        return self.readings.get("R4", "lsb")

    @classmethod
    def load(cls, name_or_path: str) -> DutProfile:
        path = find_profile(name_or_path)
        try:
            text = path.read_text(encoding="utf-8")
        except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
            known = sorted({p.name.removesuffix(".toml") for d in profile_dirs() if d.is_dir()
                            for p in d.iterdir() if p.name.endswith(".toml")})
            raise ProfileError(f"no DUT profile {name_or_path!r} (looked for {_looked_in(name_or_path)}); known by name: "
                               f"{', '.join(known)}; or give the path of a .toml file") from None
        except (OSError, UnicodeDecodeError) as exc:
            raise ProfileError(f"{path}: cannot read the DUT profile: {exc}") from None
        doc = validated(_ProfileDoc, text, path, ProfileError, lambda errors: "; ".join(_describe(path, e) for e in errors))
        return cls(name=doc.dut.name or path.name.removesuffix(".toml"), description=doc.dut.description,
                   capabilities=doc.capabilities.model_dump(), error_s=doc.timing.error_s, jitter_s=doc.timing.jitter_s,
                   boot_s=doc.timing.boot_s, off_s=doc.timing.off_s, readings=doc.readings.model_dump(), path=str(path),
                   absent=tuple(doc.functions.absent), stamp=doc.timing.stamp,
                   stated=frozenset(doc.timing.model_fields_set))


def _is_name(name_or_path: str) -> bool:
    """Whether ``--profile`` gave a bare name (looked up in :func:`profile_dirs`), not a path."""
    path = Path(name_or_path)
    return not (path.suffix or len(path.parts) > 1)


def _looked_in(name_or_path: str) -> str:
    """Every place :func:`find_profile` looked, as a missing profile's message names them."""
    if not _is_name(name_or_path):
        return str(Path(name_or_path).resolve())
    bench, shipped = profile_dirs()
    return (f"{bench / name_or_path}.toml (a bench's own profiles: fixtures/duts of the current directory), then "
            f"{shipped.joinpath(name_or_path + '.toml')} (the shipped ones)")


def find_profile(name_or_path: str) -> Any:
    """A path as given; a bare name (no suffix, no directory) in :func:`profile_dirs`."""
    if not _is_name(name_or_path):
        return Path(name_or_path)
    candidates = [d.joinpath(f"{name_or_path}.toml") for d in profile_dirs()]
    return next((c for c in candidates if c.is_file()), candidates[-1])
