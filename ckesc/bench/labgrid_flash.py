"""Flashing through labgrid (``--flash-cmd labgrid``): the image under test written by one of labgrid's own
flashing drivers on the target of the bench's labgrid environment file (``--labgrid-env``, ``--labgrid-target``,
the same the bench's ``--power labgrid`` switches through).

The driver is the target's first, in this order:

* a ``BootstrapProtocol`` driver, ``load(IMAGE)``: ``FlashromDriver`` (a ``Flashrom`` resource's programmer),
  ``OpenOCDDriver`` (an SWD/JTAG probe: most ESC MCUs), labgrid's USB loaders;
* a ``FlashScriptDriver`` on a ``USBFlashableDevice``: its script run with its ``args`` and the image's path last;
* a ``DediprogFlashDriver``: ``flash(IMAGE)``.

It runs in a process of its own (``python -m ckesc.bench.labgrid_flash``) through :func:`.firmware.flash`, like a
``--flash-cmd``: labgrid's flashing tools have no time limit of their own, and a process can be killed with every
tool it started when it hangs (``--flash-timeout``); a flash that fails, hangs, or finds no driver is exit 2 before
any verdict, one line, as a command's. labgrid is imported only in that process (the ``rig`` extra).
"""

from __future__ import annotations

import argparse
import importlib.util
import shlex
import sys
from pathlib import Path
from typing import Any

from .errors import PreflightError

#: ``--flash-cmd``'s value that flashes through labgrid
LABGRID = "labgrid"
#: labgrid's flashing drivers this module drives, by how they are called (the docstring's order)
FLASH_DRIVERS = ("BootstrapProtocol", "FlashScriptDriver", "DediprogFlashDriver")


def check(env_file: str | None) -> None:
    """``--flash-cmd labgrid``'s set-up: labgrid installed, the environment file there."""
    if importlib.util.find_spec("labgrid") is None:
        raise PreflightError('--flash-cmd labgrid needs labgrid, which is not installed here: pip install ".[rig]"')
    if not env_file:
        raise PreflightError("--flash-cmd labgrid needs --labgrid-env FILE (a labgrid environment file whose target has "
                             f"a flashing driver: {', '.join(FLASH_DRIVERS)})")
    if not Path(env_file).is_file():
        raise PreflightError(f"--labgrid-env {env_file}: no such file")


def command_line(env_file: str, target: str | None) -> str:
    """The flash command ``--flash-cmd labgrid`` stands for (``{image}`` left for :func:`.firmware.command_line`)."""
    argv = [sys.executable, "-m", __name__, "--labgrid-env", str(Path(env_file).resolve())]
    if target:
        argv += ["--labgrid-target", target]
    return " ".join(map(shlex.quote, argv)) + " {image}"


def _driver(target: Any, where: str) -> tuple[Any, Any]:
    """The target's flashing driver (the docstring's order) and how it writes an image."""
    from labgrid.exceptions import NoDriverFoundError

    for name in FLASH_DRIVERS:
        try:
            driver = target.get_driver(name, activate=False)
        except NoDriverFoundError:
            continue
        if name == "BootstrapProtocol":
            return driver, driver.load
        if name == "FlashScriptDriver":
            return driver, lambda image, script=driver: script.flash(args=[*script.args, image])
        return driver, driver.flash
    raise LookupError(f"{where} has no flashing driver ({', '.join(FLASH_DRIVERS)}: e.g. FlashromDriver on a Flashrom "
                      "resource, OpenOCDDriver on a USBDebugger)")


def flash(env_file: str, name: str | None, image: str) -> str:
    """Write ``image`` with the flashing driver of target ``name`` (default: the only one) of ``env_file``; what
    was done, or an exception whose text says what went wrong."""
    from labgrid import Environment

    env = Environment(env_file)
    try:
        targets = env.config.get_targets() or {}
        if not name:
            if len(targets) != 1:
                raise LookupError(f"it has targets {', '.join(targets) or '(none)'}: name one with --labgrid-target")
            name = next(iter(targets))
        if name not in targets:
            raise LookupError(f"no target {name!r} (targets: {', '.join(targets) or 'none'})")
        target = env.get_target(name)
        driver, write = _driver(target, f"target {name}")
        target.activate(driver)
        write(image)
        return f"labgrid: {Path(image).name} written by {type(driver).__name__} of target {name} of {env_file}"
    finally:
        env.cleanup()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m ckesc.bench.labgrid_flash", description=__doc__.split("\n\n")[0])
    p.add_argument("--labgrid-env", required=True, metavar="FILE")
    p.add_argument("--labgrid-target", metavar="NAME")
    p.add_argument("image")
    args = p.parse_args(argv)
    try:
        print(flash(args.labgrid_env, args.labgrid_target, args.image))
    except Exception as exc:  # noqa: BLE001 - labgrid's drivers raise many kinds; each is a failed flash, one line
        text = " ".join(str(exc).split()) or type(exc).__name__
        said = getattr(exc, "output", None)  # a flashing tool's CalledProcessError (labgrid's processwrapper)
        if isinstance(said, bytes) and said.strip():
            text += ": " + " ".join(said.decode(errors="replace").split())[-300:]
        print(f"labgrid flash with {args.labgrid_env}: {type(exc).__name__}: {text}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
