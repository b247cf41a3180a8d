"""DUT profiles (``fixtures/duts/*.toml``): what a device has, how precisely the lane can time it,
and which READINGs it overrides.

    [dut]          name, description
    [capabilities] led, motor, pwm_input, motor_temperature, multi_node   (true/false)
    [timing]       error_s: measurement error of the real-time lane; margins below it are INCONCLUSIVE
                   boot_s: power-on to first report; off_s: off time of a power cycle
    [readings]     R4 = "lsb" | "swapped"   (12-bit nibble order)
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

CAPABILITIES = ("led", "motor", "pwm_input", "motor_temperature", "multi_node")

#: Where profile names are looked up: the current project's fixtures/duts, then the ones shipped
#: beside this source tree (an editable install or a checkout).
PROFILE_DIRS = (Path.cwd() / "fixtures" / "duts", Path(__file__).resolve().parents[2] / "fixtures" / "duts")


@dataclass
class DutProfile:
    name: str = "unnamed"
    description: str = ""
    capabilities: dict[str, bool] = field(default_factory=dict)
    error_s: float = 0.0
    boot_s: float = 1.0
    off_s: float = 1.0
    readings: dict[str, str] = field(default_factory=dict)
    path: str | None = None

    def has(self, capability: str) -> bool:
        if capability not in CAPABILITIES:
            raise KeyError(f"unknown capability {capability!r}; known: {', '.join(CAPABILITIES)}")
        return bool(self.capabilities.get(capability, False))

    @property
    def nibble_order(self) -> str:
        return self.readings.get("R4", "lsb")

    @classmethod
    def load(cls, name_or_path: str) -> DutProfile:
        path = Path(name_or_path)
        if not path.suffix:
            candidates = [d / f"{name_or_path}.toml" for d in PROFILE_DIRS]
            path = next((c for c in candidates if c.is_file()), candidates[-1])
        try:
            doc: dict[str, Any] = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            known = sorted({p.stem for d in PROFILE_DIRS for p in d.glob("*.toml")})
            raise FileNotFoundError(f"no DUT profile {name_or_path!r} (looked for {path}); known: {', '.join(known)}; "
                                    "or give a path to a .toml file") from None
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"{path}: {exc}") from None
        caps = doc.get("capabilities", {})
        unknown = set(caps) - set(CAPABILITIES)
        if unknown:
            raise ValueError(f"{path}: unknown capabilities {sorted(unknown)}; known: {', '.join(CAPABILITIES)}")
        readings = doc.get("readings", {})
        if readings.get("R4", "lsb") not in ("lsb", "swapped"):
            raise ValueError(f"{path}: readings.R4 must be 'lsb' or 'swapped'")
        timing = doc.get("timing", {})
        return cls(name=doc.get("dut", {}).get("name", path.stem), description=doc.get("dut", {}).get("description", ""),
                   capabilities=dict(caps), error_s=float(timing.get("error_s", 0.0)),
                   boot_s=float(timing.get("boot_s", 1.0)), off_s=float(timing.get("off_s", 1.0)),
                   readings=dict(readings), path=str(path))
