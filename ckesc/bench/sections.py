"""The base of every table of a TOML file the user writes and the suite reads with pydantic (a DUT profile's
``[dut]``, ``[timing]``, ...; a rig file's head, benches and power tables): :class:`Section`. Below both readers
(:mod:`.profile`, ``ckesc/rigs/rig.py``), which import it."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict


class Section(BaseModel):
    """One table of a user's TOML file: strict (a string is not a number, a number not a string; a table may loosen
    it for its own keys) and closed (a key it does not declare is a mistake, named with the file, never ignored)."""

    model_config = ConfigDict(extra="forbid", strict=True)
