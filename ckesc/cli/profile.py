"""``ckesc profile``: DUT profiles as conformance statements (issue #29): ``show`` and ``list`` the profiles,
``init`` writes one from what the DUT answers, ``check`` says where a profile and the DUT disagree.

``init`` and ``check`` build the bench from ``ckesc run``'s bench options as every command does
(:class:`~ckesc.bench.station.BenchOptions`, :func:`~ckesc.bench.station.build`), find the DUT on it as
``ckesc explore`` does (its :class:`~ckesc.explore.runner.Session`) and ask it with reads only
(:mod:`ckesc.bench.statement`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..bench.profile import DutProfile, ProfileError, find_profile, profile_dirs
from ..reporting.exits import ExitStatus
from .common import UsageError, check_file
from .run import add_bench_options

READS_ONLY = ("The DUT is asked with reads only: GET_ESC_ID, ESC Information (240), Maintenance Information (241), "
              "Get Major Configuration (242), Set/Get Freq option 0 (214, the read), Get Rec (223) and Expand Set "
              "Part's record read (222 0xFFFB part 1); "
              "MSG3 is listened to. No setting is written and no throttle but zero is sent. MSG_EXP mode and CAN Test "
              "are modes, not reads: they are tried only with --modes (each switched on and off again at once; "
              "neither survives a power cycle, R13, R16). The bench options are ckesc run's.")


def add_profile_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "profile",
        help="show, list, write (init) and check DUT profiles: the profile as a conformance statement, checked "
             "against the DUT",
        description="A DUT profile states what the ESC has and lacks (docs/bench/profiles.md). `show` prints one, "
                    "`list` names them and where they are looked for, `init` writes one from what the DUT answers, "
                    "`check` says where a profile and the DUT disagree (warnings; exit 1 only with --strict).",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)

    show = actions.add_parser("show", help="print a profile as written (a name, as --profile takes it, or a path)",
                              description="Print a DUT profile's file as it is, after checking that it loads: "
                                          "`ckesc profile show ckesc-generic > fixtures/duts/my-esc.toml` starts your own.")
    show.add_argument("name", metavar="NAME", help="a profile name (./fixtures/duts/, then the shipped ones) or a path")
    show.set_defaults(handler=_show)

    lst = actions.add_parser("list", help="the profiles found by name, and the places looked in",
                             description="Every profile --profile NAME can name: the places looked in, in order "
                                         "(a name found in the first wins), and each profile's [dut] name.")
    lst.set_defaults(handler=_list)

    init = actions.add_parser("init", help="write a profile from what the DUT answers (reads only)",
                              description="Ask the DUT what it has and write a profile the suite accepts, with a comment "
                                          "on every key: what the DUT showed, or what a read cannot show (left at a "
                                          "stated default: 'state' or 'measure' it). " + READS_ONLY)
    add_bench_options(init)
    out = init.add_argument_group("profile init")
    out.add_argument("-o", "--output", metavar="FILE", help="write the profile here (default: standard output)")
    out.add_argument("--force", action="store_true", help="overwrite FILE if it exists")
    out.add_argument("--modes", action="store_true", help="also try MSG_EXP mode and CAN Test (see above)")
    init.set_defaults(handler=_init)

    check = actions.add_parser("check", help="the profile (--profile) against the DUT: every claim it contradicts",
                               description="Ask the DUT (as init does) and compare with the profile --profile names (the "
                                           "default: as ckesc run's). A claim the DUT contradicts is a WARNING line: "
                                           "an optional function declared absent that answers, one claimed that does "
                                           "not, a capability the DUT shows it lacks or has. Exit 0 (warnings or "
                                           "not), 1 with --strict and a warning, 2 a set-up mistake, 3 the bench "
                                           "could not be used. `ckesc run` makes the same check at its start and "
                                           "reports the warnings (never a FAIL). " + READS_ONLY)
    add_bench_options(check)
    c = check.add_argument_group("profile check")
    c.add_argument("--strict", action="store_true", help="exit 1 when a claim is contradicted")
    c.add_argument("--modes", action="store_true", help="also try MSG_EXP mode and CAN Test (see above)")
    check.set_defaults(handler=_check)


# ------------------------------------------------------------------------------------------- show, list
def _show(args: argparse.Namespace) -> int:
    try:
        DutProfile.load(args.name)
    except ProfileError as exc:
        raise UsageError(str(exc)) from None
    sys.stdout.write(find_profile(args.name).read_text(encoding="utf-8"))
    return ExitStatus.OK


def _list(args: argparse.Namespace) -> int:
    seen: set[str] = set()
    for where in profile_dirs():
        if not where.is_dir():
            print(f"{where}: (no such directory)")
            continue
        print(f"{where}:")
        for path in sorted((p for p in where.iterdir() if p.name.endswith(".toml")), key=lambda p: p.name):
            name = path.name.removesuffix(".toml")
            try:
                title = DutProfile.load(str(path)).name
            except ProfileError as exc:
                title = f"does not load: {exc}"
            hidden = " (hidden by the one above)" if name in seen else ""
            seen.add(name)
            print(f"  {name:<20} {title}{hidden}")
    return ExitStatus.OK


# ------------------------------------------------------------------------------------------- init, check
def _ask(args: argparse.Namespace):
    """Open the bench as ``ckesc explore`` does, ask the DUT, close it: (session, observed)."""
    from ..bench import statement
    from ..bench.dut import DutError
    from ..bench.lanes import BenchGone
    from ..bench.station import BenchOptions
    from ..explore import command

    try:
        session = command.open_session(BenchOptions.of(vars(args).get))
    except command.BenchProblem as exc:
        print(f"ckesc profile {args.action}: {exc}", file=sys.stderr)
        return None, None
    except ValueError as exc:
        raise UsageError(str(exc)) from None
    try:
        observed = statement.observe(statement.probe_link(session.dut), modes=args.modes)
    except (DutError, BenchGone) as exc:
        print(f"ckesc profile {args.action}: cannot use the bench: {exc}", file=sys.stderr)
        return None, None
    finally:
        session.close()
    return session, observed


def _bench_line(args: argparse.Namespace, session, observed) -> str:
    return (f"node {observed.node_id} on {session.lane.name} ({session.lane.clock} clock), --dut {args.dut}, opened with "
            f"profile {session.profile.name!r}")


def _init(args: argparse.Namespace) -> int:
    from ..bench import statement

    if args.output and Path(args.output).exists() and not args.force:
        raise UsageError(f"{args.output} exists (give --force to overwrite it)")
    check_file(args.output, "--output", "profile file")
    session, observed = _ask(args)
    if session is None:
        return ExitStatus.ABORTED
    text = statement.profile_toml(observed, opened_with=session.profile, bus=args.dut == "bus",
                                  bench=_bench_line(args, session, observed), timing_error=session.lane.timing_error)
    if not args.output:
        sys.stdout.write(text)
        return ExitStatus.OK
    Path(args.output).write_text(text, encoding="utf-8")
    DutProfile.load(args.output)  # what init writes, the suite takes (a ProfileError here is init's bug)
    absent = [n for n, s in observed.functions.items() if s.answered is False]
    print(f"wrote {args.output}: node {observed.node_id}; optional functions absent: {', '.join(absent) or 'none'}; "
          "check the keys marked 'state' and 'measure'", file=sys.stderr)
    return ExitStatus.OK


def _check(args: argparse.Namespace) -> int:
    from ..bench import statement

    session, observed = _ask(args)
    if session is None:
        return ExitStatus.ABORTED
    profile = session.profile
    print(f"profile {profile.name!r} ({profile.path}) against {_bench_line(args, session, observed)}")
    for name, seen in observed.functions.items():
        state = {True: "answers", False: "does not answer", None: "not learnt"}[seen.answered]
        claim = "declared absent" if name in profile.absent else "claimed"
        print(f"  {name:<16} {claim:<16} {state}: {seen.how}")
    warnings = statement.contradictions(profile, observed, bus=args.dut == "bus")
    for w in warnings:
        print(f"WARNING: {w}")
    print(f"{len(warnings)} claim(s) of the profile contradicted by the DUT" if warnings
          else "no claim of the profile is contradicted by what the DUT showed")
    return ExitStatus.FAILED if warnings and args.strict else ExitStatus.OK
