"""python-can interfaces that fail as real adapters do, for the tests of bus faults mid-run (issue #11).

``flaky`` (socketcand) and ``flaky-virtual`` (python-can's virtual bus) work until the process has sent
``fail_after`` frames; that send raises ``can.CanOperationError`` as a bus-off adapter does, and the
bus reports ``BusState.ERROR``. With ``recover`` true a reopened bus works again (the adapter came
back from bus-off); with it false the adapter is gone: opening it raises ``can.CanInitializationError``
as an unplugged USB adapter does. With ``full_tries`` N the failure is SocketCAN's full transmit queue instead: the
next N tries raise ``can.CanOperationError`` with ENOBUFS (the queue draining meanwhile), then sends go again. Every
option comes as a python-can bus argument (``--can-config``).
"""

from __future__ import annotations

import errno
from typing import Any

import can
from can.interfaces.socketcand import SocketCanDaemonBus
from can.interfaces.virtual import VirtualBus

#: per process: frames sent through any flaky bus, and whether the failure has happened
SENT = 0
FAILED = False


class _Flaky:
    def _flaky_init(self, fail_after: Any, recover: Any, full_tries: Any = 0) -> None:
        if FAILED and not _true(recover):
            raise can.CanInitializationError("flaky: no such device (the adapter was unplugged)")
        self.fail_after = int(fail_after)
        self.full_tries = int(full_tries)
        self.queue_only = self.full_tries > 0  # (then no bus-off)
        self.failed_here = False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        global SENT, FAILED
        if self.full_tries and SENT >= self.fail_after:
            self.full_tries -= 1
            raise can.CanOperationError("Failed to transmit: No buffer space available", errno.ENOBUFS)
        if not FAILED:
            SENT += 1
            if SENT > self.fail_after and not self.queue_only:
                FAILED = self.failed_here = True
                raise can.CanOperationError("flaky: transmit failed, the controller is bus-off")
        super().send(msg, timeout)  # type: ignore[misc]

    @property
    def state(self) -> can.BusState:
        return can.BusState.ERROR if self.failed_here else can.BusState.ACTIVE


class FlakySocketcand(_Flaky, SocketCanDaemonBus):
    def __init__(self, channel: str, *, fail_after: Any = 100, recover: Any = True, full_tries: Any = 0,
                 **kwargs: Any) -> None:
        self._flaky_init(fail_after, recover, full_tries)
        super().__init__(channel, **kwargs)


class FlakyVirtual(_Flaky, VirtualBus):
    def __init__(self, channel: str, *, fail_after: Any = 100, recover: Any = True, full_tries: Any = 0,
                 **kwargs: Any) -> None:
        self._flaky_init(fail_after, recover, full_tries)
        super().__init__(channel, **kwargs)


def _true(value: Any) -> bool:
    return value if isinstance(value, bool) else str(value).lower() in ("1", "true", "yes")


def reset() -> None:
    global SENT, FAILED
    SENT, FAILED = 0, False
