"""The bench's errors, shared by the bench's parts, the session's preflight and the conformance tests: a set-up
mistake found before any test (:class:`PreflightError`, exit status 2), and the suite itself failing under a test
(:class:`HarnessError`, :class:`BenchError`: that test's verdict is ERROR, never the DUT's FAIL). The verdict is
told by the exception's type, never by a word in its message."""

from __future__ import annotations


class PreflightError(Exception):
    """A set-up mistake: the message is one line naming what is wrong and, where there is one, the way out."""


class HarnessError(RuntimeError):
    """The suite, not the DUT, could not do what a test needed (its own stream sent nothing, a request did not go
    out as built, a load it set up is not the one it meant): the test ERRORs with this message, whatever the
    requirement's strength. A conformance test raises it (``raise HarnessError("...")``) where the problem is its
    own; an ``assert`` is a verdict on the DUT."""


class RestoreFailed(HarnessError):
    """The harness could not put the bench back as the test found it (the DUT's node id, throttle channel, bit rate,
    settings), or could not verify it had: the test ERRORs with this message whatever the requirement's strength, an
    OBSERVE test's too. It is told apart from the DUT not answering what a test asked
    (:class:`~ckesc.bench.link.DutError`), which in an OBSERVE test is what the DUT did: a restore that meets a DUT
    not answering raises this (:func:`~ckesc.bench.link.restoring`). The explorer's reset between programs raises it
    too (:meth:`~ckesc.explore.runner.Session.run`): the exploration stops, with no finding."""


class BenchError(HarnessError):
    """The bench, not the DUT, failed under a test (a power command that failed or never returned): the test
    ERRORs with this message, whatever the requirement's strength."""


class PowerFailed(BenchError):
    """The power control could not switch: its command failed, timed out, or its backend raised."""
