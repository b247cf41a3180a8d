"""The image under test (issue #37): flashed before the bench proof, then proven to be the one running.

``--firmware IMAGE`` names the image; ``--flash-cmd "CMD {image}"`` writes it into the DUT (``{image}`` replaced by
the image's path, quoted), run without a shell within ``--flash-timeout`` s (:func:`flash`); a flash that cannot
start, exits non-zero or hangs is a :class:`.errors.PreflightError`, exit 2 before any verdict. Where the flash
tool does not reset the ESC, the bench's power control does: the bench proof's power cycle (:mod:`.proof`), proven
by the DUT falling silent and reporting again like any other.

What ESC Information 240 must then answer is said by, first found: ``--expect-firmware KEY=VALUE,...``, a sidecar
``IMAGE.toml`` (the image's path with ``.toml`` added), ``firmware.toml`` beside the image, or, for an emulator
image, the image itself. A sidecar is the emulator image's own format, its ``[esc_information]`` table::

    [esc_information]
    firmware_date = "2024-10-11"     # YYYY-MM-DD, as the reports write 240's date
    protocol_version = 21
    hardware_version = 3

An **emulator image** (a ``.toml`` file with an ``[esc_information]`` table) is what ``--dut emulator`` "flashes":
the emulated ESC answers 240 as it says and plays its ``faults`` (emulator fault names) and ``options``
(``NAME=VALUE`` conforming variants, as ``--emulator-option``), e.g. a release with a regression::

    faults = ["esc_information_bcd_date"]
    options = ["report_timer=grid"]
    [esc_information]
    firmware_date = "2024-11-02"

:func:`mismatches` judges 240's answer against the expectation, the one rule, pure; :func:`prove` says it as the
one line a wrong image gets.
"""

from __future__ import annotations

import hashlib
import re
import shlex
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..protocol import catalogue as cat
from .errors import PowerFailed, PreflightError
from .power import output_tail, run_command

#: How long a flash may run before it has failed (``--flash-timeout``): an ESC's MCU is written over SWD or its
#: bootloader in well under a minute; two leave room for a slow probe and a verify pass, and a tool that hangs (a
#: probe that does not answer) must not hold a CI job for ever
FLASH_TIMEOUT_S = 120.0
#: how much of the flash tool's output the reports keep (its end: where a tool says what it did)
OUTPUT_KEPT = 600
#: the ``--flash-cmd`` of an emulator image: no command, the emulated ESC takes the image as it starts
BUILTIN = "builtin"

#: what 240's answer is compared by: the key an expectation gives -> how it is read from a string
_KEYS: dict[str, Any] = {"firmware_date": str, "protocol_version": int, "hardware_version": int, "max_cells": int,
                         "max_current": float}
_DATE = re.compile(r"^20(\d\d)-(\d\d)-(\d\d)$")


@dataclass(frozen=True)
class Image:
    """A firmware image: its path and SHA-256, what 240 must answer (``expected``, said by ``said_by``) and, for an
    emulator image, what the emulated ESC plays (``esc_config``: EscConfig fields; ``faults``; ``options``)."""

    path: Path
    sha256: str
    expected: dict[str, Any]
    said_by: str
    emulated: bool = False
    esc_config: dict[str, Any] = field(default_factory=dict)
    faults: tuple[str, ...] = ()
    options: tuple[str, ...] = ()


def _checked(key: str, value: Any, where: str) -> Any:
    if key not in _KEYS:
        raise PreflightError(f"{where}: {key!r} is not a field 240 answers (known: {', '.join(_KEYS)})")
    try:
        value = _KEYS[key](value)
    except (TypeError, ValueError):
        kind = {"int": "a whole number", "float": "a number"}.get(_KEYS[key].__name__, "text")
        raise PreflightError(f"{where}: {key} = {value!r} is not {kind}") from None
    if key == "firmware_date" and not _DATE.match(value):
        raise PreflightError(f"{where}: firmware_date = {value!r} is not a date YYYY-MM-DD from 2000 on")
    return value


def parse_expect(text: str) -> dict[str, Any]:
    """``--expect-firmware firmware_date=2024-10-11,protocol_version=21`` -> the expectation, checked."""
    out: dict[str, Any] = {}
    for item in (p.strip() for p in text.split(",")):
        key, eq, value = item.partition("=")
        if not eq:
            raise PreflightError(f"--expect-firmware: {item!r} is not KEY=VALUE (e.g. firmware_date=2024-10-11)")
        out[key.strip()] = _checked(key.strip(), value.strip(), "--expect-firmware")
    return out


def _table(path: Path) -> dict[str, Any]:
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, tomllib.TOMLDecodeError) as exc:
        raise PreflightError(f"{path}: not a readable TOML file ({exc})") from None


def _esc_information(doc: dict[str, Any], where: Path) -> dict[str, Any]:
    table = doc.get("esc_information")
    if not isinstance(table, dict) or not table:
        raise PreflightError(f"{where}: no [esc_information] table saying what 240 answers (firmware_date = "
                             "\"YYYY-MM-DD\", protocol_version, hardware_version)")
    return {k: _checked(k, v, f"{where} [esc_information]") for k, v in table.items()}


def load(path: str, expect: str | None = None) -> Image:
    """The image at ``path`` with its expectation (the module's docstring says where it is found); a
    :class:`PreflightError` for a missing image, a bad sidecar, or nothing saying what 240 must answer."""
    image = Path(path)
    try:
        data = image.read_bytes()
    except OSError as exc:
        raise PreflightError(f"--firmware {path}: {exc.strerror or exc}") from None
    doc = _table(image) if image.suffix == ".toml" else {}
    emulated = "esc_information" in doc
    own = _esc_information(doc, image) if emulated else {}
    sidecars = [image.with_name(image.name + ".toml"), image.with_name("firmware.toml")]
    found = next((p for p in sidecars if p.is_file() and p != image), None)
    if expect:
        expected, said_by = parse_expect(expect), "--expect-firmware"
    elif found is not None:
        expected, said_by = _esc_information(_table(found), found), found.name
    elif emulated:
        expected, said_by = own, image.name
    else:
        raise PreflightError(f"--firmware {path}: nothing says what ESC Information (240) must answer: write "
                             f"{image.name}.toml or firmware.toml beside it ([esc_information] firmware_date, "
                             "protocol_version, hardware_version), or give --expect-firmware KEY=VALUE,...")
    faults, options = doc.get("faults", []), doc.get("options", [])
    if not (isinstance(faults, list) and isinstance(options, list)):
        raise PreflightError(f"{image}: faults and options are lists of strings (faults = [\"NAME\"], options = "
                             "[\"NAME=VALUE\"])")
    return Image(path=image.resolve(), sha256=hashlib.sha256(data).hexdigest(), expected=expected, said_by=said_by,
                 emulated=emulated, esc_config=esc_config(own), faults=tuple(map(str, faults)),
                 options=tuple(map(str, options)))


def esc_config(answer: dict[str, Any]) -> dict[str, Any]:
    """An emulator image's 240 answer as the emulated ESC's EscConfig fields."""
    out: dict[str, Any] = {}
    if "firmware_date" in answer:
        out["firmware_date"] = tuple(int(g) for g in _DATE.match(answer["firmware_date"]).groups())  # type: ignore[union-attr]
    for key in ("protocol_version", "hardware_version", "max_cells"):
        if key in answer:
            out[key] = answer[key]
    if "max_current" in answer:
        out["max_current_10a"] = round(answer["max_current"] / 10)
    return out


def answered(fields: dict[str, Any] | None) -> dict[str, Any] | None:
    """240's answer (its fields, physical) in the expectation's keys: ``firmware_date`` as ``YYYY-MM-DD``."""
    if fields is None:
        return None
    out = {k: fields[k] for k in _KEYS if k in fields}
    if date := cat.firmware_date(fields):
        out["firmware_date"] = date
    return out


def mismatches(expected: dict[str, Any], answer: dict[str, Any]) -> list[str]:
    """The expected keys 240's answer (:func:`answered`) does not match, each ``KEY`` (the rule, pure)."""
    return [k for k, v in expected.items() if answer.get(k) != v]


def _said(values: dict[str, Any], keys: list[str]) -> str:
    return ", ".join(f"{k}={values.get(k, 'nothing')}" for k in keys)


def prove(image: Image, fields: dict[str, Any] | None) -> str:
    """240's answer (``fields``; None: no answer) against the image's expectation: what was proven, or the one line
    (a :class:`PreflightError`) a DUT running another image gets."""
    answer = answered(fields)
    if answer is None:
        raise PreflightError(f"the image under test is not proven to be the one running: 240 gave no answer, "
                             f"{image.said_by} says {_said(image.expected, list(image.expected))}")
    wrong = mismatches(image.expected, answer)
    if wrong:
        raise PreflightError(f"the image under test is not the one running: 240 says {_said(answer, wrong)}, "
                             f"{image.said_by} says {_said(image.expected, wrong)}")
    return f"firmware: {image.path.name} (sha256 {image.sha256[:12]}) is running: 240 says {_said(answer, list(image.expected))}"


def command_line(cmd: str, image: Image) -> str:
    """``--flash-cmd`` with ``{image}`` replaced by the image's path (quoted as a shell word)."""
    return cmd.replace("{image}", shlex.quote(str(image.path)))


def flash(image: Image, cmd: str, timeout: float = FLASH_TIMEOUT_S) -> str:
    """Run the flash command (:func:`command_line`) and return its output's tail; a flash that cannot start, fails
    or hangs (killed at ``timeout``) is a :class:`PreflightError`."""
    if cmd == BUILTIN:
        return ""
    try:
        out = run_command(command_line(cmd, image), timeout, what="flash command", longer="--flash-timeout")
    except PowerFailed as exc:
        raise PreflightError(f"flash of {image.path.name}: {exc}") from None
    return output_tail(out, OUTPUT_KEPT)


def report(image: Image, cmd: str | None, output: str, fields: dict[str, Any] | None) -> dict[str, Any]:
    """The run's ``info["firmware"]``: the image, its SHA-256, the flash command and its output's tail, what 240
    was expected to answer and what it answered (flat: each a JUnit property ``firmware.<key>``)."""
    return {"image": str(image.path), "sha256": image.sha256, "flash_cmd": cmd or "", "flash_output": output,
            "expected": f"{_said(image.expected, list(image.expected))} ({image.said_by})",
            "answered": _said(answered(fields) or {}, list(image.expected)) if fields is not None else "no answer"}
