"""Physical readings the report sections check for plausibility: voltage and current against the
ESC's own limits (MSG2, MSG_EXP1), temperatures (MSG3, MSG_EXP11, MSG_EXP12). Physics, not protocol
(not a section: no tests here).
"""

from __future__ import annotations

from ckesc.bench.outcomes import Inconclusive
from ckesc.protocol import catalogue as cat

#: Physics, not protocol: a LiHV cell full is 4.35 V; no drone ESC runs below two cells at 3.0 V.
#: A reading in the wrong unit (0.1 V, 1 mV) falls outside [2 x 3.0 V, max_cells x 4.35 V].
CELL_FULL_V = 4.35
MIN_SUPPLY_V = 2 * 3.0
#: Physics, not protocol: an ESC above 150 degC is destroyed, not reporting; two readings of one
#: sensor a few report intervals apart agree within a few degrees.
MAX_PLAUSIBLE_C = 150
SAME_SENSOR_C = 3


def esc_limits(dut) -> tuple[int, float]:
    """(max cells, max current in A) from ESC Information (240)."""
    info = dut.ask("esc_information", {"option": 0})
    layout = cat.spec("esc_information").response
    cells, amps = info["max_cells"], layout.field("max_current").physical(info["max_current"])
    dut.record.observe("ESC Information", f"{cells} S, {amps} A")
    if not cells or not amps:
        raise Inconclusive(f"ESC Information (240) gives {cells} S / {amps} A: no bound to check the units against")
    return cells, amps


def check_voltage_current(dut, frames: list, cells: int, amps: float, what: str, requirement: str) -> None:
    """Voltage and current are unsigned 0.01 V / 0.01 A: in range for the ESC's cells and current."""
    volts = [f.physical()["voltage"] for f in frames]
    currents = [f.physical()["current"] for f in frames]
    dut.record.observe(f"{what} voltage (V)", f"{min(volts)}..{max(volts)}")
    dut.record.observe(f"{what} current (A)", f"{min(currents)}..{max(currents)}")
    rec = dut.record
    rec.measure(f"{what} voltage, lowest", min(volts), limit=MIN_SUPPLY_V, op=">=", unit="V", clock=dut.clock,
                requirement=requirement)
    rec.measure(f"{what} voltage, highest", max(volts), limit=round(cells * CELL_FULL_V, 6), unit="V",
                clock=dut.clock, requirement=requirement)
    rec.measure(f"{what} current, highest (unsigned: a negative value reads as ~655 A)", max(currents), limit=amps,
                unit="A", clock=dut.clock, requirement=requirement)
