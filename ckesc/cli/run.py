"""``ckesc run``: its arguments; :mod:`ckesc.run` runs the suite with them."""

from __future__ import annotations

import argparse

from .. import run as run_lib
from ..harness.traces import TRACE_FORMATS


def add_bench_options(p: argparse.ArgumentParser) -> argparse._ArgumentGroup:
    """The bench options ``ckesc run`` and ``ckesc explore`` share (the device under test, its lane and power)."""
    g = p.add_argument_group("device under test")
    g.add_argument("--dut", choices=("emulator", "bus"), default="emulator", help="default: emulator")
    g.add_argument("--lane", choices=("simulated", "realtime"), default="simulated",
                   help="for --dut emulator: simulated time (default) or a separate real-time process")
    g.add_argument("--can-interface", help="python-can interface for --dut bus (else can.conf / CAN_INTERFACE)")
    g.add_argument("--can-channel", help="python-can channel, e.g. can0")
    g.add_argument("--can-bitrate", type=int, help="bit rate of the host's bus")
    g.add_argument("--can-config", action="append", default=[], metavar="KEY=VALUE", help="extra bus argument (repeatable)")
    g.add_argument("--can-bitrate-cmd", metavar="CMD",
                   help="--dut bus: command that moves the host's bus to {bitrate} when Set Baud's tests need it "
                        "(python-can cannot set a SocketCAN bit rate; see README, Firmware qualification)")
    g.add_argument("--host-send-error", type=float, metavar="MS",
                   help="an adapter that does not echo the host's frames: how much later than the host clock at send "
                        "a frame may reach the bus, ms (default 2): the error of times taken from the host's frames")
    g.add_argument("--node-id", type=int, help="the DUT's node id (default: discovered with GET_ESC_ID)")
    g.add_argument("--nodes", help="emulator: node ids of the emulated bench (default 1)")
    g.add_argument("--profile", help="DUT profile name (fixtures/duts) or path")
    g.add_argument("--power", choices=("emulator", "command", "labgrid", "manual", "none"), help="power control")
    g.add_argument("--power-off-cmd", help="--power command: switches the DUT off")
    g.add_argument("--power-on-cmd", help="--power command: switches the DUT on")
    g.add_argument("--labgrid-env", metavar="FILE", help="--power labgrid: labgrid environment file (a target with a power driver)")
    g.add_argument("--labgrid-target", metavar="NAME", help="--power labgrid: the target in --labgrid-env (default: its only one)")
    g.add_argument("--labgrid-place", metavar="NAME",
                   help="--power labgrid: acquire this labgrid place for the run, release it at the end (default: the "
                        "target's RemotePlace, if any)")
    g.add_argument("--labgrid-coordinator", metavar="HOST:PORT",
                   help="--power labgrid: the labgrid coordinator (default: the env file's coordinator_address, "
                        "LG_COORDINATOR, 127.0.0.1:20408)")
    g.add_argument("--allow-motor-spin", action="store_true", default=None,
                   help="allow non-zero throttle on a real ESC (propellers off!)")
    g.add_argument("--emulator-faults", default="", help="emulator: comma-separated fault names to switch on")
    g.add_argument("--emulator-seed", type=int, default=0)
    g.add_argument("--emulator-option", action="append", default=[], metavar="NAME=VALUE",
                   help="emulator: one conforming variant for every emulated ESC (repeatable; names, values and the "
                   "requirements that allow each: ckesc emulate --list-variants)")
    g.add_argument("--emulator-variants", type=int, default=None, metavar="SEED",
                   help="emulator: play the conforming combination drawn from SEED (--emulator-option wins over it)")
    return g


def add_run_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "run",
        help="run the conformance suite against a DUT and write reports",
        description=run_lib.__doc__.split("\n\n")[1] if run_lib.__doc__ else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Select sections by number or test modules by path: `ckesc run 4.4.22 4.4.3`, `ckesc run "
               "conformance/test_s4_4_22_set_freq.py`; a selection that matches nothing is an error (exit 2). Any "
               "other pytest option can follow `--`, e.g. `ckesc run -- -k set_freq -x`.",
    )
    r = p.add_argument_group("several benches at once (pytest-xdist: pip install 'ckesc-conformance[rig]')")
    r.add_argument("--rig", metavar="FILE", help="a rig file (fixtures/rigs/*.toml): run on every bench of it at once, one "
                   "pytest-xdist worker per bench; each bench's report in <reports>/<timestamp>/<bench>/, and batch.html, "
                   "batch.json and a merged junit.xml beside them. The options below are then set per bench by the rig")
    r.add_argument("--benches", metavar="A,B", help="--rig: only these benches (default: every bench of the rig)")
    g = add_bench_options(p)
    g.add_argument("--order", choices=("overlap", "collection"), default="overlap",
                   help="overlap (default): tests that neither power-cycle nor reconfigure the DUT run while a 120 s "
                   "Set ID / Set Baud window elapses, persistence tests share power cycles; collection: one test "
                   "after another, each with its own waits and cycles (verdicts are the same)")
    o = p.add_argument_group("output")
    o.add_argument("--reports", default="reports", metavar="DIR", help="where reports go (default: reports/)")
    o.add_argument("--strict", action="store_true", help="INCONCLUSIVE results fail the run too")
    o.add_argument("--trace-format", choices=TRACE_FORMATS, default="blf",
                   help="each test's CAN traffic under <run>/traces/: blf (default), asc, log (candump), none")
    o.add_argument("-q", "--quiet", action="store_true", help="no per-test progress lines")
    o.add_argument("--progress", choices=("on", "off"), default="on",
                   help="a line per section with the protocol time planned, spent and an estimate of what is left "
                   "(default on; on a terminal also after pytest's counter)")
    o.add_argument("--time-from", metavar="RESULTS_JSON",
                   help="estimate the time left from this earlier run of the bench (its results.json; default: the "
                   "suite's own table of a faultless simulated run)")
    p.add_argument("pytest_args", nargs=argparse.REMAINDER, metavar="SECTION|MODULE ... [-- PYTEST_ARGS]",
                   help="sections (4.4.22), test modules by name or path; after --: passed to pytest")

    def handler(args: argparse.Namespace) -> int:
        # argparse hands everything from the first free argument on to pytest_args: ckesc run's own options
        # after a section (`ckesc run 4.4.22 --strict`) are taken back here; the rest goes to pytest
        tokens = list(args.pytest_args)
        cut = tokens.index("--") if "--" in tokens else len(tokens)
        mine, rest, i = [], [], 0
        while i < cut:
            action = p._option_string_actions.get(tokens[i].split("=")[0])  # noqa: SLF001 - argparse has no public lookup
            take = 1 if action is None or "=" in tokens[i] or action.nargs == 0 else 2
            (mine if action is not None else rest).extend(tokens[i:i + take])
            i += take
        if mine:
            p.parse_args(mine, namespace=args)
        args.pytest_args = rest + tokens[cut:]
        return run_lib.run_command(args)

    p.set_defaults(handler=handler)
