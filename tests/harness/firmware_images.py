"""A series of emulator images (docs/firmware.md) as a release history, for the tests that flash, gate and bisect:
:func:`series` writes ``count`` images, oldest first, each a day newer than the one before (240's firmware date
tells them apart), the image numbered ``bad_from`` (1-based) and every later one with ``fault`` switched on."""

from __future__ import annotations

import datetime
from pathlib import Path

#: the regression the series introduces: 241 option 2 swaps the power-up and stop counters (4.4.27-T), which
#: section 4.4.27 finds in well under a second of simulated time
FAULT = "maintenance_counts_wrong"
FIRST_DATE = datetime.date(2024, 1, 1)


def series(where: Path, count: int = 32, bad_from: int = 19, fault: str = FAULT) -> list[Path]:
    """``count`` images ``build-01.toml`` ... in ``where`` and ``images.txt`` listing them oldest first; the paths."""
    paths = []
    for n in range(1, count + 1):
        date = FIRST_DATE + datetime.timedelta(days=n - 1)
        faults = f'["{fault}"]' if n >= bad_from else "[]"
        path = where / f"build-{n:02d}.toml"
        path.write_text(f"# build {n} of {count}\nfaults = {faults}\noptions = []\n\n[esc_information]\n"
                        f'firmware_date = "{date.isoformat()}"\nprotocol_version = 21\nhardware_version = 3\n',
                        encoding="utf-8")
        paths.append(path)
    (where / "images.txt").write_text("".join(f"{p}\n" for p in paths), encoding="utf-8")
    return paths
