"""The bench's errors, shared by the bench's parts and the session's preflight: a set-up mistake found before
any test (:class:`PreflightError`, exit status 2) and the bench failing under a test (:class:`BenchError`: that
test's verdict is ERROR, never the DUT's FAIL)."""

from __future__ import annotations


class PreflightError(Exception):
    """A set-up mistake: the message is one line naming what is wrong and, where there is one, the way out."""


class BenchError(RuntimeError):
    """The bench, not the DUT, failed under a test (a power command that failed or never returned): the test
    ERRORs with this message, whatever the requirement's strength."""


class PowerFailed(BenchError):
    """The power control could not switch: its command failed, timed out, or its backend raised."""
