"""The bus-fault relay through labgrid (``--bus-fault-cmd labgrid``, R20): a relay whose contacts short CANH to CANL
at the ESC's connector, switched by one of labgrid's own ``DigitalOutputProtocol`` drivers on the target of the
bench's labgrid environment file (``--labgrid-env``, ``--labgrid-target``: the same the bench's ``--power labgrid``
and ``--flash-cmd labgrid`` use): a USB relay board (``HIDRelayDriver``, ``DeditecRelaisDriver``), a GPIO
(``GpioDigitalOutputDriver``), an Ethernet or Modbus relay (``Eth008DigitalOutputDriver``, ``ModbusCoilDriver``),
an HTTP one (``HttpDigitalOutputDriver``), a file (``FileDigitalOutputDriver``: sysfs), an operator
(``ManualSwitchDriver``) ... with no code of ours.

A short is ``set(True)`` for the fault's seconds, then ``set(False)``; the relay is opened (``set(False)``) when the
bench is opened (one left closed by an earlier run), after every fault whatever happened meanwhile (Ctrl-C, a
failed read), and when the bench is closed (the run's end, an abort, SIGTERM: the station's close, which the session
registers as a cleanup). Only a process killed outright (SIGKILL) can leave it closed: the next run opens it first.
A relay causes a short only: the R20 test of a node at another bit rate SKIPs, saying so.

labgrid is imported only here and only when it is asked for (the ``rig`` extra), as for power and flashing.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from typing import Any

from .errors import PreflightError
from .labgrid_power import environment, one_line, open_driver

#: ``--bus-fault-cmd``'s value that shorts the bus through labgrid
LABGRID = "labgrid"
#: the labgrid protocol whose driver switches the relay
PROTOCOL = "DigitalOutputProtocol"


def check(env_file: str | None) -> None:
    """``--bus-fault-cmd labgrid``'s set-up that opens nothing: labgrid installed, the environment file there."""
    if importlib.util.find_spec("labgrid") is None:
        raise PreflightError('--bus-fault-cmd labgrid needs labgrid, which is not installed here: pip install ".[rig]"')
    if not env_file:
        raise PreflightError(f"--bus-fault-cmd labgrid needs --labgrid-env FILE (a labgrid environment file whose target "
                             f"has a relay driver: {PROTOCOL}, e.g. HIDRelayDriver on a HIDRelay)")
    if not Path(env_file).is_file():
        raise PreflightError(f"--labgrid-env {env_file}: no such file")


class LabgridRelay:
    """The bench's bus-fault control (:mod:`.bus_fault`'s protocol: ``can``, ``cause``, ``settle``) through a
    labgrid relay driver; ``lane``, set when the bench's lane opens, reads the bus while the relay is closed."""

    def __init__(self, driver: Any, where: str, env: Any) -> None:
        self.driver, self.where, self.env = driver, where, env
        self.lane: Any = None
        self.switched: list[bool] = []  # what it was asked, in order (the reports and tests read it)

    def _set(self, closed: bool) -> None:
        from .bus_fault import BusFaultFailed

        self.switched.append(closed)
        try:
            self.driver.set(closed)
        except Exception as exc:  # noqa: BLE001 - a driver may raise anything (USB, HTTP, Modbus ...)
            how = "close" if closed else "open"
            raise BusFaultFailed(f"the bus-fault relay did not {how} ({self.where}): {one_line(exc)}") from exc

    def can(self, kind: str) -> bool:
        return kind == "short"

    def cause(self, kind: str, seconds: float) -> float | None:
        """Close the relay for ``seconds``, reading the bus meanwhile; open it again on every way out."""
        if kind != "short":
            raise ValueError(f"a relay across CANH-CANL causes a short, not {kind!r}")
        try:
            self._set(True)
            self.lane.wait_power(seconds)
        finally:
            self._set(False)
        return None  # it ended as the relay opened

    def settle(self, within: float = 0.0) -> bool:
        return True

    def close(self) -> None:
        """The relay opened, the driver deactivated (idempotent)."""
        env, self.env = self.env, None
        if env is None:
            return
        try:
            if self.driver is not None:
                self._set(False)
        except Exception:  # noqa: BLE001 - said on the way out, never over the run's own result
            print(f"ckesc: could not open the bus-fault relay ({self.where}) on the way out: open it by hand",
                  file=sys.stderr)
        finally:
            try:
                env.cleanup()
            except Exception:  # noqa: BLE001
                pass


def open_relay(env_file: str, name: str | None) -> LabgridRelay:
    """The relay driver of target ``name`` (default: the only one) of ``env_file``, activated and opened; every
    set-up problem a :class:`PreflightError` naming the file and the target."""
    check(env_file)
    env, name = environment(env_file, name)
    where = f"target {name} of {env_file}"
    relay = LabgridRelay(None, where, env)
    try:
        driver = open_driver(env, name, PROTOCOL, where, unusable="the bus-fault relay",
                             missing=f"--bus-fault-cmd labgrid: {where} has no relay driver ({PROTOCOL}: e.g. "
                                     "HIDRelayDriver on a HIDRelay, GpioDigitalOutputDriver on a SysfsGPIO)")
        relay.driver, relay.where = driver, f"{type(driver).__name__} of {where}"
        try:
            relay._set(False)  # one left closed (a run killed mid-fault) is opened before anything is judged
        except Exception as exc:  # noqa: BLE001
            raise PreflightError(str(exc)) from None
    except BaseException:
        relay.close()
        raise
    return relay
