"""Whether a command can read what it was given and write where it was told to, asked before any work and without leaving anything made (issue #38):
a reports directory that is missing is fine when it could be made, a file in the way or a directory this user cannot
write into is one line that names the option. The command line (``ckesc/cli/common.py``) and a run's preflight
(``ckesc/session/preflight.py``) say it in the same words, :func:`not_writable`."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def _nearest(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists."""
    while not os.path.lexists(path) and path != path.parent:
        path = path.parent
    return path


def _refused(where: Path) -> str | None:
    """Why this user cannot make entries in the existing directory ``where`` (None: it can). Where the permissions
    say yes, the kernel is asked too, with an entry made and removed at once: root passes ``os.access`` everywhere,
    and /proc, sysfs or a read-only mount refuse it anyway."""
    if os.access(where, os.W_OK | os.X_OK):
        try:
            os.rmdir(tempfile.mkdtemp(prefix=".ckesc-probe-", dir=where))
            return None
        except OSError as exc:
            return f"{where}: {(exc.strerror or str(exc)).lower()}"
    try:
        if os.statvfs(where).f_flag & os.ST_RDONLY:
            return f"{where} is on a read-only file system"
    except OSError:
        pass
    return f"{where}: permission denied"


def why_not_writable(path: str | os.PathLike, *, file: bool = False) -> str | None:
    """Why files cannot be written in the directory ``path`` (made with its parents when missing), or with ``file``
    why the file ``path`` cannot be written (its directory must exist); None when they can. Makes nothing."""
    given = Path(path).expanduser()
    if file:
        if given.is_dir():
            return f"{given} is a directory"
        if given.exists():
            return None if os.access(given, os.W_OK) else f"{given}: permission denied"
        parent = given.parent
        if not parent.is_dir():
            return f"{parent} is not a directory" if parent.exists() else f"no directory {parent}"
        return _refused(parent)
    if given.is_dir():
        return _refused(given)
    nearest = _nearest(given)
    if not nearest.is_dir():
        return f"{nearest} is not a directory" if nearest.exists() else f"nothing of {given} exists"
    return _refused(nearest)


def not_writable(path: str | os.PathLike, option: str, what: str, *, file: bool = False) -> str | None:
    """The one line a command says when it cannot write ``what`` ("reports directory", "output file") at ``path``,
    given with ``option``; None when it can (:func:`why_not_writable`)."""
    why = why_not_writable(path, file=file)
    return None if why is None else f"{what} {str(path)!r} is not writable ({why}): give another with {option}"


def not_readable(path: str | os.PathLike, option: str, what: str) -> str | None:
    """The one line a command says when it cannot read the file ``what`` ("replay file") at ``path``, given with
    ``option``; None when it can. The same shape as :func:`not_writable`'s."""
    given = Path(path).expanduser()
    if given.is_file():
        why = None if os.access(given, os.R_OK) else "permission denied"
    else:
        why = "a directory, not a file" if given.is_dir() else "no such file" if not given.exists() else "not a file"
    return None if why is None else f"{what} {str(path)!r} is not readable ({why}): give another with {option}"
