"""The bisect's IO side: the image list read (:func:`image_list`), each run of a step a real ``ckesc run --firmware
IMAGE ... SELECTION`` in its own process, its report read back (:func:`run_once`), and the bisect driven to its end
by :class:`.core.Bisection` (:func:`bisect`).

A run's exit status says its outcome, from the one exit table (:class:`ckesc.reporting.exits.ExitStatus`): OK is
GOOD (the selection passed), FAILED is BAD (a test FAILed or ERRORed), anything else (the flash failed, the image was
not the one running, the bench went away, the run was stopped) a bench error. Its ``results.json`` gives the
failing tests and the image's SHA-256 for the bisect's report; a GOOD or BAD run without one is a bench error too.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..reporting.exits import ExitStatus
from .core import BisectEnd, Bisection, Outcome, Step

#: what a run's exit status says of its image
OUTCOMES = {ExitStatus.OK: Outcome.GOOD, ExitStatus.FAILED: Outcome.BAD}
#: how much of a failed run's console the step's line and report keep (its end: where ``ckesc run`` says why)
TAIL = 300
#: the verdicts that fail a run, as results.json writes them
FAILING = ("FAIL", "ERROR")


def image_list(path: str) -> list[Path]:
    """The images of ``--images LIST``, oldest first: a file of paths (one a line, relative to the file; blank
    lines and ``#`` comments skipped) or a directory's files (an image's sidecar, ``IMAGE.toml`` or ``firmware.toml``,
    left out) ordered by the firmware date each says 240 answers (:func:`by_firmware_date`), by name where one does
    not say it. A :class:`ValueError` in one line for a list with fewer than 2 images or one that names a missing
    file."""
    where = Path(path)
    if where.is_dir():
        files = sorted(p for p in where.iterdir() if p.is_file() and not p.name.startswith("."))
        names = {p.name for p in files}
        images = [p for p in files if p.name != "firmware.toml" and not (p.suffix == ".toml" and p.stem in names)]
        if not images:
            raise ValueError(f"--images {path}: the directory holds no image")
        images = by_firmware_date(images)
    else:
        lines = (ln.split("#", 1)[0].strip() for ln in where.read_text(encoding="utf-8").splitlines())
        images = [(where.parent / ln) for ln in lines if ln]
    if len(images) < 2:
        raise ValueError(f"--images {path}: {len(images)} image(s): a bisect needs the known-good image first and the "
                         "known-bad one last")
    missing = next((p for p in images if not p.is_file()), None)
    if missing is not None:
        raise ValueError(f"--images {path}: {missing} is not a file")
    return images


def by_firmware_date(images: list[Path]) -> list[Path]:
    """``images`` (in name order) ordered by the firmware date 240 must answer for each (its expectation as
    ``ckesc run --firmware`` finds it: a sidecar, or an emulator image's own), the name deciding between equal dates;
    in name order when one of them says no date (a build history is ordered one way, never by a mix of the two)."""
    from ..bench.errors import PreflightError
    from ..bench.firmware import load

    dates = []
    for image in images:
        try:
            dates.append(str(load(str(image)).expected["firmware_date"]))
        except (PreflightError, KeyError, OSError, ValueError):
            return images
    return [image for _, image in sorted(zip(dates, images), key=lambda pair: pair[0])]


def regressed_tests(old: str, new: str) -> list[str]:
    """The tests that passed in the run ``old`` and do not in the run ``new`` (``ckesc compare``'s regressions): a
    bisect's selection "whatever regressed in this compare". A :class:`ValueError` in one line when none did or a run
    cannot be read."""
    from ..reporting.compare import diff, read_run
    from ..reporting.comparing import RunError

    try:
        changes = diff(read_run(old), read_run(new))
    except RunError as exc:
        raise ValueError(f"--regressed: {exc}") from None
    tests = [row["test"] for row in changes["tests"]["regressed"]]
    if not tests:
        raise ValueError(f"--regressed {old} {new}: no test regressed between them: nothing to bisect")
    return tests


@dataclass
class StepRun:
    """One run of a step: its outcome, seconds of wall time, where its report is, the failing tests, the image's
    SHA-256 (from results.json) and, for a bench error, the end of its console."""

    outcome: Outcome
    seconds: float
    reports: str
    status: int
    failing: list[str] = field(default_factory=list)
    sha256: str | None = None
    said: str = ""


def run_once(image: Path, run_args: Sequence[str], selection: Sequence[str], out: Path) -> StepRun:
    """``ckesc run --firmware IMAGE RUN_ARGS --reports OUT -q SELECTION``, its console in ``OUT/console.txt``."""
    out.mkdir(parents=True, exist_ok=True)
    argv = [sys.executable, "-m", "ckesc", "run", "--firmware", str(image), *run_args, "--reports", str(out), "-q",
            *selection]
    started = time.monotonic()
    with open(out / "console.txt", "w", encoding="utf-8") as console:
        console.write(" ".join(argv) + "\n")
        console.flush()
        status = subprocess.run(argv, stdout=console, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL).returncode
    seconds = time.monotonic() - started
    outcome = OUTCOMES.get(status, Outcome.ERROR)
    run = StepRun(outcome, seconds, str(out), status)
    try:
        doc = json.loads((out / "latest" / "results.json").read_text(encoding="utf-8"))
        run.failing = [r["nodeid"] for r in doc["results"] if r.get("outcome") in FAILING]
        run.sha256 = (doc["info"].get("firmware") or {}).get("sha256")
        run.reports = str((out / "latest").resolve())
    except (OSError, ValueError, KeyError, TypeError):
        if outcome is not Outcome.ERROR:
            run.outcome = Outcome.ERROR
    if run.outcome is Outcome.ERROR:
        text = (out / "console.txt").read_text(encoding="utf-8", errors="replace").strip().splitlines()
        run.said = (text[-1] if len(text) > 1 else f"exit status {status}")[-TAIL:]
    return run


Runner = Callable[[Path, Path], StepRun]


@dataclass
class Bisect:
    """A bisect's record: the images, its options, every step's runs (in order, with the core's steps) and its end."""

    images: list[Path]
    tries: int
    canary: str
    selection: list[str]
    steps: list[tuple[Step, list[StepRun]]] = field(default_factory=list)
    result: BisectEnd | None = None
    seconds: float = 0.0
    interrupted: bool = False

    def name(self, i: int) -> str:
        return f"{i + 1}/{len(self.images)} {self.images[i]}"

    def record(self) -> dict[str, Any]:
        r = self.result
        return {
            "kind": "bisect", "images": [str(p) for p in self.images], "tries": self.tries, "canary": self.canary,
            "selection": self.selection, "seconds": round(self.seconds, 2), "runs": sum(len(rs) for _, rs in self.steps),
            "bisect_steps": sum(1 for s, _ in self.steps if not s.canary),
            "ending": r.ending.value if r else ("interrupted" if self.interrupted else None), "reason": r.reason if r else None,
            "first_bad": None if r is None or r.first_bad is None else {"number": r.first_bad + 1,
                                                                        "image": str(self.images[r.first_bad])},
            "last_good": None if r is None else {"number": r.good + 1, "image": str(self.images[r.good])},
            "interrupted": self.interrupted,
            "steps": [{"image": str(self.images[s.image]), "number": s.image + 1, "canary": s.canary,
                       "verdict": s.verdict.value if s.verdict else None,
                       "runs": [{"outcome": run.outcome.value, "seconds": round(run.seconds, 2), "status": run.status,
                                 "reports": run.reports, "failing": run.failing, "sha256": run.sha256,
                                 **({"said": run.said} if run.said else {})} for run in runs]}
                      for s, runs in self.steps],
        }


def step_line(b: Bisect, n: int, step: Step, runs: list[StepRun]) -> str:
    """The console's line for a step: which, the image, each run's outcome, the verdict, the time."""
    what = "canary" if step.canary else f"step {n}"
    verdict = step.verdict.value if step.verdict else "no verdict"
    said = next((f" ({r.said})" for r in runs if r.said), "")
    return (f"{what}: image {b.name(step.image)}: {', '.join(r.outcome.value for r in runs)} -> {verdict}{said} "
            f"[{sum(r.seconds for r in runs):.1f} s]")


def bisect(images: list[Path], selection: Sequence[str], runner: Runner, steps_dir: Path, *, tries: int = 1,
           canary: str = "end", say: Callable[[str], None] = print) -> Bisect:
    """Bisect ``images`` (oldest first, the first good and the last bad) with ``runner(image, out_dir)`` running one
    try (:func:`run_once`, its arguments bound), a line said per step; the record of every step and the end."""
    b = Bisect(list(images), tries, canary, list(selection))
    machine = Bisection(len(images), tries=tries, canary=canary)
    started = time.monotonic()
    runs: list[StepRun] = []
    bisect_steps = 0
    try:
        while machine.next_image is not None:
            step, image = machine.step, machine.next_image
            run = runner(images[image], steps_dir / f"{len(b.steps) + 1:02d}-{images[image].stem}-{len(runs) + 1}")
            runs.append(run)
            if machine.record(run.outcome) is not None:
                b.steps.append((step, runs))
                bisect_steps += not step.canary
                say(step_line(b, bisect_steps, step, runs))
                runs = []
    except KeyboardInterrupt:  # Ctrl-C: the step's run stopped with zero throttle (its own handler); the steps so far reported
        b.interrupted = True
    b.result, b.seconds = machine.result, time.monotonic() - started
    return b
