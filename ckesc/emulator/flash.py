"""The emulator's flash: what R13 says persists, kept in a JSON file written atomically.

A write goes to a temporary file in the same folder, is flushed and fsync'ed, then renamed over
the old file (and the folder fsync'ed), so a crash mid-write leaves the previous contents intact.
A file that cannot be read is never silently replaced: :class:`FlashError` says what is wrong.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path
from typing import Any

FORMAT = "ckesc-emulator-flash/1"


class FlashError(RuntimeError):
    pass


class FlashStore:
    """Persisted settings and counters of a bench, one entry per slot (an ESC's place on the bench,
    which stays fixed while its node id changes)."""

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)

    def load(self) -> dict[int, dict[str, Any]]:
        try:
            text = self.path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return {}
        except UnicodeDecodeError as exc:
            raise FlashError(f"{self.path}: not a flash file (not UTF-8 text); move it away to start from factory state") from exc
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise FlashError(f"{self.path}: not a flash file ({exc}); move it away to start from factory state") from exc
        if not isinstance(doc, dict) or doc.get("format") != FORMAT or not isinstance(doc.get("slots"), dict):
            raise FlashError(f"{self.path}: not a {FORMAT} file; move it away to start from factory state")
        slots: dict[int, dict[str, Any]] = {}
        for key, value in doc["slots"].items():
            if not key.isdigit() or not isinstance(value, dict):
                raise FlashError(f"{self.path}: slot {key!r} is not a slot number with a settings table; "
                                 "move the file away to start from factory state")
            slots[int(key)] = value
        return slots

    def save(self, slots: dict[int, dict[str, Any]]) -> None:
        doc = {"format": FORMAT, "slots": {str(k): v for k, v in sorted(slots.items())}}
        data = json.dumps(doc, indent=1, sort_keys=True).encode()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=self.path.name + ".", suffix=".tmp", dir=self.path.parent)
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)
        except BaseException:
            try:
                os.unlink(tmp)
            except FileNotFoundError:
                pass
            raise
        dir_fd = os.open(self.path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
