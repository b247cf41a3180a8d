"""The bench's set-up error, shared by the bench's parts and the session's preflight."""

from __future__ import annotations


class PreflightError(Exception):
    """A set-up mistake: the message is one line naming what is wrong and, where there is one, the way out."""
