"""The document's functions, and which of them a DUT profile may declare absent (R9b).

1-2: "Some functions are only available on ESCs configured with the appropriate hardware"; 4.2.1:
other functions depend on the ESC model. A DUT profile lists what its ESC lacks
(``[functions] absent = [...]``, names from :data:`OPTIONAL`); the tests of an absent function are
SKIPPED as "not claimed" and every report says what the conformance claim leaves out. What R9b
says cannot be left out is :data:`CORE`: declaring one of those absent is a set-up error.

Each optional function lists what it covers, once:

* ``requirements``: a test citing one of them is a test of the function (skipped before it starts);
* ``frames``: requests the host sends only for this function (a test that sends one, e.g. to read
  something it compares with, is skipped at that point);
* ``commands``: MSG Control commands that use the function (0xEEEEEEEE: MSG_EXP mode).

Names are the catalogue's frame names where a function is one frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

from .catalogue import MSG_CONTROL_RESUME_EXP


@dataclass(frozen=True)
class Function:
    name: str
    title: str
    sections: tuple[str, ...]
    requirements: tuple[str, ...] = ()
    frames: tuple[str, ...] = ()
    commands: tuple[int, ...] = ()

    def describe(self) -> str:
        return f"{self.name} ({self.title}, {', '.join(self.sections)})"


#: What a profile may declare absent (R9b). Other functions the suite needs for its own work (242 to
#: read settings, 241 to prove a power cycle, Set Rotation / Throttle Select to restore settings,
#: Set Led: capability ``led``) are not listed here.
_OPTIONAL = (
    Function("msg_exp_mode", "MSG_EXP mode: MSG Control 0xEEEEEEEE and the MSG_EXP1..11 frames",
             ("4.4.2", "4.4.7", "4.4.8", "4.4.9", "4.4.10", "4.4.11", "4.4.12", "4.4.13"),
             requirements=("R9-exp", "4.4.7-T", "4.4.8-T", "4.4.9-T", "4.4.10-T", "4.4.11-T", "4.4.12-T", "4.4.13-T"),
             commands=(MSG_CONTROL_RESUME_EXP,)),
    Function("get_rec", "Get Rec / Clear Rec (223, 224) and the MSG_EXP12 temperature records",
             ("4.4.14", "4.4.25"), requirements=("R15", "R15-payload", "4.4.14-T"), frames=("get_rec", "clear_rec")),
    Function("expand_set_part", "Expand Set Part (222)", ("4.4.25",),
             requirements=("R14", "4.4.25-1", "4.4.25-2", "4.4.25-T"), frames=("expand_set_part",)),
    Function("can_test", "CAN Test mode (20000)", ("4.4.1",),
             requirements=("R16", "4.4.1-1", "4.4.1-2", "4.4.1-3", "4.4.1-4"), frames=("can_test",)),
)

#: What R9b says a profile cannot leave out (names for the error message; sections 4.1 and 4.3 are
#: the framing and frame table every frame obeys).
CORE: MappingProxyType[str, str] = MappingProxyType({
    "framing": "4.1", "frame_table": "4.3", "get_esc_id": "4.4.3", "msg_control": "4.4.2", "msg1": "4.4.4",
    "msg2": "4.4.5", "msg3": "4.4.6", "raw_command_14b": "4.4.15", "raw_command_12b": "4.4.16",
    "raw_command_10b": "4.4.17", "set_id": "4.4.18", "set_baud": "4.4.19", "set_freq": "4.4.22",
    "esc_information": "4.4.26",
})

OPTIONAL: MappingProxyType[str, Function] = MappingProxyType({f.name: f for f in _OPTIONAL})


def of_requirements(ids, absent) -> list[Function]:
    """The absent functions (names in ``absent``) a test citing ``ids`` is a test of."""
    cited = set(ids)
    return [OPTIONAL[n] for n in absent if cited & set(OPTIONAL[n].requirements)]


def of_request(name: str, fields, absent) -> Function | None:
    """The absent function that sending frame ``name`` with ``fields`` would use, if any."""
    command = (fields or {}).get("command") if name == "msg_control" else None
    for n in absent:
        f = OPTIONAL[n]
        if name in f.frames or (command is not None and command in f.commands):
            return f
    return None


def not_claimed_text(absent) -> str:
    """One line for the reports: what the conformance claim leaves out ("" for nothing)."""
    return "; ".join(OPTIONAL[n].describe() for n in absent)
