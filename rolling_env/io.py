"""Atomic file writes: a result is either the old file or the complete new one."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path


def atomic_write(path: str | os.PathLike, writer) -> Path:
    """Call ``writer(tmp_path)`` on a temporary file beside ``path``, then rename it into
    place (``os.replace`` is atomic on POSIX); on any error the temporary file is removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    try:
        writer(tmp)
        _give_mode(tmp, path)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def _read_umask() -> int:
    mask = os.umask(0o022)  # the only way to read it; done once, at import, not per write
    os.umask(mask)
    return mask


_UMASK = _read_umask()


def _give_mode(tmp, path: Path) -> None:
    """mkstemp makes the file owner-only (0600); give it the mode a plain open() would: an
    existing file's own mode (open() keeps it when overwriting), else 0666 less the umask.
    Where the file system refuses chmod, the write still goes ahead."""
    try:
        mode = path.stat().st_mode & 0o777 if path.exists() else 0o666 & ~_UMASK
        os.chmod(tmp, mode)
    except OSError:
        pass


def write_text(path, text: str) -> Path:
    return atomic_write(path, lambda p: Path(p).write_text(text))
