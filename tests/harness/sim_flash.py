"""A stand-in flash tool for bisects in simulation (``--flash-cmd "python sim_flash.py [--flaky NAME] [--sticky]
{image}"``), for the benches a bisect must not be fooled by. An emulator image is read by ``ckesc run`` before its
flash step, so what a flash does shows from the next run on: this tool plays the bench's memory by writing the
images (copies in a test's directory, :func:`firmware_images.series`) that the next runs load.

``--flaky NAME``: the image NAME shows its fault one run in three (runs 1, 4, 7, ... of it; the first run shows it,
so a bisect with one try believes it): after each flash of it, its ``faults`` line is written for its next run.

``--sticky``: the bench keeps state: once an image with faults was flashed, every image of the directory has them
(the fault stays on the bench whatever is flashed next), which only the canary can see.

The count of each image's flashes is kept in ``.flashes.json`` beside the images."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

FAULTS_LINE = re.compile(r"^faults = .*$", re.M)


def faults_of(image: Path) -> str:
    return FAULTS_LINE.search(image.read_text(encoding="utf-8")).group(0)  # type: ignore[union-attr]


def write_faults(image: Path, line: str) -> None:
    image.write_text(FAULTS_LINE.sub(line, image.read_text(encoding="utf-8"), count=1), encoding="utf-8")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--flaky", default=None, help="the image file's name that shows its fault one run in three")
    p.add_argument("--fault", default="maintenance_counts_wrong", help="the flaky image's fault")
    p.add_argument("--sticky", action="store_true")
    p.add_argument("image", type=Path)
    a = p.parse_args(argv)
    counts_file = a.image.parent / ".flashes.json"
    counts = json.loads(counts_file.read_text()) if counts_file.is_file() else {}
    counts[a.image.name] = flashed = counts.get(a.image.name, 0) + 1
    counts_file.write_text(json.dumps(counts))
    if a.flaky == a.image.name:  # the next run (flashed + 1) shows the fault when it is run 1, 4, 7, ...
        write_faults(a.image, f'faults = ["{a.fault}"]' if flashed % 3 == 0 else "faults = []")
    if a.sticky and (line := faults_of(a.image)) != "faults = []":
        for other in a.image.parent.glob("*.toml"):
            write_faults(other, line)
    print(f"flashed {a.image.name} ({flashed} time(s))")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
