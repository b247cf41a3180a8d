"""Helpers for the tests that run the tool as a user does: ``ckesc`` processes with a clean environment."""

from __future__ import annotations

import os
import sys
from pathlib import Path

CKESC = [sys.executable, "-m", "ckesc"]


def env(tmp: Path) -> dict[str, str]:
    """The environment of a ``ckesc`` process under ``tmp``: its own temp directory, unbuffered output, and
    no python-can configuration from the caller's environment."""
    (tmp / "tmp").mkdir(exist_ok=True)
    out = dict(os.environ, TMPDIR=str(tmp / "tmp"), PYTHONUNBUFFERED="1")
    for key in ("CAN_INTERFACE", "CAN_CHANNEL", "CAN_BITRATE", "CAN_CONFIG"):
        out.pop(key, None)
    return out
