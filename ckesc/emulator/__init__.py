"""The CKESC ESC emulator: a sans-IO model, switchable faults, a flash store, and two lanes
(simulated time as a python-can interface, real time in its own process)."""

from .faults import FAULTS, Fault
from .model import EscConfig, EscModel, factory_nvm
