"""What every power backend is (:class:`PowerControl`: it switches the DUT's supply) and the two callables its
factory is given (``get``: the bench's options by name; ``prompt``: asks the operator). Below the backends
(:mod:`.power`, :mod:`.labgrid_power`, another package's ``ckesc.power`` entry point) and their registry
(:func:`.power.backends`), which all import it."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any

#: the bench's options by name, as a backend's factory reads them (:meth:`.station.BenchOptions.get`)
Option = Callable[[str], Any]
#: asks the operator (``--power manual``), returns when they have done it
Prompt = Callable[[str], None]


class PowerControl(ABC):
    """Switches the DUT's supply. ``available`` False: tests that need a power cycle are skipped."""

    name = "power"
    available = True

    @abstractmethod
    def off(self) -> None: ...

    @abstractmethod
    def on(self) -> None: ...
