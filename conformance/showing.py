"""Commands that show when they are taken: for every frame type the ESC takes from the host, a valid command whose
effect the host can see afterwards (a setting moved, a suspend, CAN Test on, an answer, a comm refresh). The robustness
section sends them where the ESC must take nothing: malformed (R17), and at another bit rate than the ESC's (R20). Not
a section: no tests.

Not sent: Clear Rec (taking it erases the ESC's temperature records, which nothing can put back); Set ID and Set Baud
write only inside the 120 s window after a power-up (R11), so a test sends them there, on its own terms.
"""

from __future__ import annotations

from ckesc.protocol import Status
from ckesc.protocol import catalogue as cat
from ckesc.protocol import malformed as r17

from .settings import NEIGHBOURS, move_request
from .throttle import command_for

#: the requests that write a setting only inside the 120 s window after power-up (R11)
WINDOW_WRITERS = frozenset(s.writer for s in cat.PERSISTED_SETTINGS if s.window)
#: taking it erases the ESC's temperature records, which nothing reads back
DESTRUCTIVE = frozenset({"clear_rec"})
#: a read of the temperature records (Expand Set Part): taking it shows as MSG_EXP12 frames
READ_RECORDS = next(c for c in cat.EXPAND_COMMANDS.values() if c.name == "read_temperature_records")

#: every frame type the ESC takes from the host, in the catalogue's order, less those not sent (module docstring)
TAKEN = [s.name for s in cat.CATALOGUE if r17.host_layout(s) is not None and s.name not in WINDOW_WRITERS | DESTRUCTIVE]
#: the persisted setting each writer moves
_WRITES = {cat.PERSISTED[name].writer: name for name in NEIGHBOURS}

#: a command of each frame type that shows if it is taken (the settings writers and the throttle frames have theirs
#: from their tables): a frame type added to the catalogue without one fails here, at import
_COMMANDS = {
    "can_test": lambda dut, s: {"option": cat.CAN_TEST_ON},
    "msg_control": lambda dut, s: {"option": 0, "command": cat.MSG_CONTROL_SUSPEND},
    "get_esc_id": lambda dut, s: {"option": 0},
    "self_test": lambda dut, s: {},
    "expand_set_part": lambda dut, s: {"set_cmd": READ_RECORDS.code, "part": next(iter(READ_RECORDS.parts))},
    "get_rec": lambda dut, s: {"payload": []},
    "esc_information": lambda dut, s: {"option": 0},
    "maintenance_information": lambda dut, s: {"option": 2},
    "get_major_configuration": lambda dut, s: {"option": 0},
}
if missing := sorted(set(TAKEN) - set(_COMMANDS) - set(_WRITES) - set(cat.THROTTLE_FRAMES)):
    raise KeyError(f"frame types {missing}: say in {__name__} which command of theirs shows when taken")


def command(dut, name: str, s: dict, value: int = 0) -> dict | None:
    """The fields of a valid command of ``name`` that shows if it is taken (None: the DUT's channel is not in it)."""
    if name in _WRITES:
        return move_request(_WRITES[name], s)
    if name in cat.THROTTLE_FRAMES:
        return command_for(name, s["throttle_channel"], value)
    return _COMMANDS[name](dut, s)


def state_bits(f) -> int:
    """MSG1 ``f``'s state bits but the comm flag (which moves with time, R8): a command taken shows in them."""
    return f.fields["status"] & (cat.STATUS_STATE_BITS & ~Status.COMM_FAULT)
