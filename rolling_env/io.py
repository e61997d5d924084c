"""Atomic file writes: a result is either the old file or the complete new one.

``atomic_write`` writes one file through a temporary file beside it.  Inside
``with staged():`` every ``atomic_write`` (at any depth of the calls) only writes its
temporary file; the block's end renames them all into place, and an error anywhere in the
block removes them all, so a command that writes several files (a CSV and its plot, the
paper figures, the comparison tables) leaves either all of them new or all of them as they
were: a full disk halfway no longer leaves a new CSV beside an old plot.
"""

from __future__ import annotations

import contextlib
import contextvars
import errno
import os
import signal
import tempfile
import threading
from pathlib import Path

# the staged writes of the innermost ``staged()`` block: [(tmp, path), ...], or None
_STAGE: contextvars.ContextVar[list | None] = contextvars.ContextVar("_STAGE", default=None)


@contextlib.contextmanager
def _handler_swapped(sig, expected, handler):
    """Signal ``sig`` handled by ``handler`` for the block where it is ``expected`` now (and
    this is the main thread, the only one that may set handlers); ``expected`` again after
    it."""
    if (
        threading.current_thread() is not threading.main_thread()
        or signal.getsignal(sig) is not expected
    ):
        yield  # e.g. SIGINT ignored (a script's background job) or someone else's handler
        return
    signal.signal(sig, handler)
    try:
        yield
    finally:
        signal.signal(sig, expected)


def _sigint_swapped(expected, handler):
    return _handler_swapped(signal.SIGINT, expected, handler)


def _raise_terminated(signum, frame):
    """SIGTERM (``timeout``, job schedulers) as SystemExit(128 + signal): the writes below
    then remove their temporary files and the process still exits 143, as the OS default
    would have it."""
    raise SystemExit(128 + signum)


def interrupt_ends_process():
    """Ctrl-C ends the process inside the block (the OS default for SIGINT), also in the
    middle of a long compiled kernel call, which never returns to the interpreter to raise
    KeyboardInterrupt (a simulate of 1e9 sub-steps ran on for minutes).  The CLI runs its
    commands so; the writes below switch KeyboardInterrupt back on (``interrupt_raises``)."""
    return _sigint_swapped(signal.default_int_handler, signal.SIG_DFL)


@contextlib.contextmanager
def interrupt_raises():
    """Ctrl-C raises KeyboardInterrupt inside the block even within ``interrupt_ends_process``,
    and SIGTERM, where it has the OS default (ending the process at once), raises
    SystemExit(143): the writes below then remove their temporary files instead of leaving
    them behind.  A no-op where the signals have other handlers."""
    with (
        _sigint_swapped(signal.SIG_DFL, signal.default_int_handler),
        _handler_swapped(signal.SIGTERM, signal.SIG_DFL, _raise_terminated),
    ):
        yield


def atomic_write(path: str | os.PathLike, writer) -> Path:
    """Call ``writer(tmp_path)`` on a temporary file beside ``path``, then rename it into
    place (``os.replace`` is atomic on POSIX); on any error the temporary file is removed.
    Inside ``staged()`` the rename waits for the end of the block."""
    with interrupt_raises():
        return _atomic_write(path, writer)


def _atomic_write(path, writer) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_dir():  # the rename would fail: say so before anything is written
        raise IsADirectoryError(
            errno.EISDIR, "a folder has the name of the file to write", str(path)
        )
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.stem}.", suffix=path.suffix)
    os.close(fd)
    stage = _STAGE.get()
    try:
        writer(tmp)
        _give_mode(tmp, path)
        if stage is None:
            os.replace(tmp, path)
        else:
            stage.append((tmp, path))
    except BaseException:
        _remove(tmp)
        raise
    return path


@contextlib.contextmanager
def staged():
    """Write every file of the block together: all renamed into place at its end, none if
    it raises (see the module docstring).  Nested blocks join the outer one.  The renames
    themselves are not one atomic step, but they cannot run out of space: what fails in
    practice (a full disk, an unwritable folder, an error while rendering) fails while
    writing the temporary files, before any target changes."""
    if _STAGE.get() is not None:  # nested: the outer block commits
        yield
        return
    with interrupt_raises():
        stage: list = []
        token = _STAGE.set(stage)
        try:
            yield
        except BaseException:
            for tmp, _ in stage:
                _remove(tmp)
            raise
        finally:
            _STAGE.reset(token)
        for k, (tmp, path) in enumerate(stage):
            try:
                os.replace(tmp, path)
            except BaseException:
                for left, _ in stage[k:]:
                    _remove(left)
                raise


def _remove(tmp) -> None:
    try:
        os.unlink(tmp)
    except FileNotFoundError:
        pass


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


def check_writable(path, folder: bool = False, name: str = "out") -> Path:
    """Raise OSError naming ``name`` unless the folder ``path`` (``folder``) or the folder of
    the file ``path`` can take new files: for a command to call before it computes anything,
    so that an unwritable --out fails at once, not after the work.  Creates nothing: it
    probes the nearest folder that exists with a temporary file (the writes make the missing
    folders below it, as before)."""
    path = Path(path)
    d = path if folder else path.parent
    up = next((p for p in (d, *d.parents) if p.exists() or p.is_symlink()), Path("."))
    if not up.is_dir():
        raise NotADirectoryError(
            f"--{name}: cannot write {str(path)!r}: {str(up)!r} is a file, not a folder"
        )
    try:
        with tempfile.NamedTemporaryFile(dir=up, prefix=".probe."):
            pass
    except OSError as e:
        raise OSError(
            f"--{name}: cannot write {str(path)!r}: the folder {str(up)!r} takes no "
            f"new files ({e.strerror or e})"
        ) from None
    return path


def write_text(path, text: str) -> Path:
    return atomic_write(path, lambda p: Path(p).write_text(text))
