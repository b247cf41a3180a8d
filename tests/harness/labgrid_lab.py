"""A labgrid lab on 127.0.0.1 for the tests of ``--power labgrid``: a power switch that speaks labgrid's
``simplerest`` model (labgrid/driver/power/simplerest.py) in front of a ``ckesc emulate`` process, and a real
``labgrid-coordinator`` and ``labgrid-exporter`` exporting it."""

from __future__ import annotations

import re
import socket
import subprocess
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

from procs import end

from ckesc.emulator.control import control_request

LOCALHOST = "127.0.0.1"


class _Answering(BaseHTTPRequestHandler):
    """A request handler that answers with a short text body and logs nothing."""

    def answer(self, body: str) -> None:
        self.send_response(200)
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body.encode())

    def log_message(self, *args) -> None:
        pass


class _Served:
    """An HTTP server of ``handler`` on a free port of 127.0.0.1, served by a thread of its own until :meth:`close`;
    ``url`` is its address with ``path``."""

    def _serve(self, handler: type[BaseHTTPRequestHandler], path: str) -> None:
        self.server = ThreadingHTTPServer((LOCALHOST, 0), handler)
        self.url = f"http://{LOCALHOST}:{self.server.server_address[1]}{path}"
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


class PowerSwitch(_Served):
    """An HTTP relay for labgrid's NetworkPowerPort ``model: simplerest``: ``GET /power/<index>/<1|0>`` switches the
    emulator's power through its control channel (as ``ckesc control --port P power on|off`` does), ``GET
    /power/<index>`` answers ``1`` or ``0``. ``switched`` lists what it was asked to do, in order."""

    def __init__(self, control_port: int) -> None:
        self.control_port = control_port
        self.switched: list[str] = []
        switch = self

        class Handler(_Answering):
            def do_GET(self) -> None:  # noqa: N802 - http.server's name
                m = re.fullmatch(r"/power/(\d+)(?:/([01]))?", self.path)
                if m is None:
                    self.send_error(404)
                    return
                if m.group(2) is not None:
                    action = "on" if m.group(2) == "1" else "off"
                    control_request(switch.control_port, {"cmd": "power", "action": action})
                    switch.switched.append(action)
                    body = m.group(2)
                else:
                    body = "1" if control_request(switch.control_port, {"cmd": "status"})["powered"] else "0"
                self.answer(body)

        self._serve(Handler, "/power/{index}/{value}")


def free_port() -> int:
    with socket.socket() as s:
        s.bind((LOCALHOST, 0))
        return s.getsockname()[1]


def _wait_for(what: str, ready, proc: subprocess.Popen, log: Path, timeout: float = 60) -> None:
    deadline = time.monotonic() + timeout
    while not ready():
        if proc.poll() is not None or time.monotonic() > deadline:
            raise RuntimeError(f"{what} did not come up: {log.read_text()[-2000:]}")
        time.sleep(0.2)


class Lab:
    """``labgrid-coordinator`` on a free port of 127.0.0.1 (its places in ``where``) and a ``labgrid-exporter`` named
    ``exporter`` exporting, in group ``bench``, the NetworkPowerPort ``power`` whose switch is ``url``."""

    def __init__(self, where: Path, url: str, env: dict[str, str]) -> None:
        self.where, self.env = where, env
        self.address = f"{LOCALHOST}:{free_port()}"
        self.procs: list[subprocess.Popen] = []
        clog = where / "coordinator.log"
        coordinator = self._start(["labgrid-coordinator", "--listen", self.address], clog)
        _wait_for("labgrid-coordinator", lambda: "listening on" in clog.read_text(), coordinator, clog)
        (where / "exporter.yaml").write_text(
            f"bench:\n  power:\n    cls: NetworkPowerPort\n    model: simplerest\n    host: '{url}'\n    index: 0\n")
        elog = where / "exporter.log"
        exporter = self._start(["labgrid-exporter", "--coordinator", self.address, "--name", "exporter", "--hostname",
                                LOCALHOST, str(where / "exporter.yaml")], elog)
        _wait_for("labgrid-exporter", lambda: "exporter/bench/NetworkPowerPort" in self.client("resources").stdout,
                  exporter, elog)

    def _start(self, argv: list[str], log: Path) -> subprocess.Popen:
        with log.open("w") as out:
            proc = subprocess.Popen(argv, cwd=self.where, env=self.env, stdout=out, stderr=subprocess.STDOUT)
        self.procs.append(proc)
        return proc

    def client(self, *args: str, user: str | None = None) -> subprocess.CompletedProcess:
        """``labgrid-client`` against this coordinator (as ``user``: LG_USERNAME, labgrid's own way to be someone else)."""
        env = dict(self.env, **({"LG_USERNAME": user} if user else {}))
        return subprocess.run(["labgrid-client", "--coordinator", self.address, *args], cwd=self.where, env=env,
                              capture_output=True, text=True, timeout=60)

    def place(self, name: str) -> None:
        """Create place ``name`` holding the exported power port."""
        for args in (("create",), ("add-match", "exporter/bench/NetworkPowerPort/power")):
            done = self.client("-p", name, *args)
            assert done.returncode == 0, done.stderr

    def holder(self, name: str) -> str | None:
        """Who has acquired place ``name`` (host/user), or None."""
        show = self.client("-p", name, "show").stdout
        m = re.search(r"^\s*acquired: (.+)$", show, re.M)
        assert m, show
        return None if m.group(1).strip() == "None" else m.group(1).strip()

    def close(self) -> None:
        for proc in reversed(self.procs):
            end(proc)


class BusRelay(_Served):
    """An HTTP relay for labgrid's ``HttpDigitalOutput`` (``HttpDigitalOutputDriver``) whose contacts short the
    emulator's bus: ``PUT /relay`` with ``1`` closes it (``ckesc control bus short on`` through the control channel),
    ``0`` opens it (``... off``); ``GET /relay`` answers ``1`` or ``0``. ``switched`` lists what it was asked, in
    order; ``on_close`` (if set) is called each time it closes, after the bus is shorted."""

    def __init__(self, control_port: int) -> None:
        self.control_port = control_port
        self.switched: list[int] = []
        self.closed = False
        self.on_close = None
        relay = self

        class Handler(_Answering):
            def do_PUT(self) -> None:  # noqa: N802 - http.server's name
                body = self.rfile.read(int(self.headers.get("Content-Length") or 0)).decode().strip()
                if self.path != "/relay" or body not in ("0", "1"):
                    self.send_error(404 if self.path != "/relay" else 400)
                    return
                closed = body == "1"
                if closed != relay.closed:
                    control_request(relay.control_port, {"cmd": "bus_fault", "kind": "short", "on": closed})
                relay.closed = closed
                relay.switched.append(int(closed))
                self.answer(body)
                if closed and relay.on_close is not None:
                    relay.on_close()

            def do_GET(self) -> None:  # noqa: N802
                self.answer("1" if relay.closed else "0")

        self._serve(Handler, "/relay")

    def env_file(self, where: Path) -> Path:
        """A labgrid environment file: target ``esc`` with this relay as an HttpDigitalOutput and labgrid's own
        HttpDigitalOutputDriver on it."""
        path = where / "relay.yaml"
        path.write_text("targets:\n  esc:\n    resources:\n      HttpDigitalOutput:\n"
                        f"        url: '{self.url}'\n        body_asserted: '1'\n        body_deasserted: '0'\n"
                        "    drivers:\n      HttpDigitalOutputDriver: {}\n")
        return path
