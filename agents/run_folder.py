"""The run folder of ``agents.train``: trained in a staging folder beside it and moved into
place at the end, so that a folder holds one whole run; a folder the script did not create,
or one with files it does not write, is never replaced."""

from __future__ import annotations

import os
import re
import shutil
import signal
import sys
from pathlib import Path

from .common import (
    UsageError,
)


def staging_folder(run: Path) -> Path:
    """Where ``--overwrite`` trains before it replaces ``run``: ``<run>.overwrite`` beside it
    (a stopped or failed run's files, its checkpoint among them, stay there)."""
    return run.with_name(run.name + ".overwrite")


def _replace_run(run: Path, work: Path) -> None:
    """Put the finished run in ``work`` in place of the earlier run ``run`` (checked again by
    ``_not_a_run``: it may have changed while training): two renames with SIGINT and SIGTERM
    held back between them, then the earlier run is deleted (a failure there only warns).
    Where the earlier run may not be replaced any more, both are kept and a UsageError says
    where the new one is."""
    if not run.exists() and not run.is_symlink():  # deleted while training
        os.rename(work, run)
        return
    why = _not_a_run(run)
    if why:
        raise UsageError(
            f"the new run is complete in {str(work)!r}, but {str(run)!r} {why} "
            "now (changed while training): nothing was deleted"
        )
    old = run.with_name(f".{run.name}.replaced-{os.getpid()}")
    held = {signal.SIGINT, signal.SIGTERM}
    mask = getattr(signal, "pthread_sigmask", lambda how, sigs: None)  # POSIX only
    mask(signal.SIG_BLOCK, held)
    try:
        os.rename(run, old)
        try:
            os.rename(work, run)
        except BaseException:
            os.rename(old, run)
            raise
    finally:
        mask(signal.SIG_UNBLOCK, held)
    try:  # signals no longer held: deleting a large tb/ takes a while
        shutil.rmtree(old)
    except OSError as e:  # the new run is in place: warn, leave the hidden folder
        print(
            f"python -m agents.train: warning: the new run is in {str(run)!r}, but the "
            f"earlier run left in {str(old)!r} could not be deleted ({e.strerror or e})",
            file=sys.stderr,
        )


RUN_MARKER = "rolling-drive-run.txt"  # written when the script creates a run folder
RUN_FILES = re.compile(  # what the script (and SB3's TensorBoard logger) writes in a run folder
    r"^(config\.yml|command\.txt|meta\.json|evaluations\.npz|eval_goal\.json|tb|"
    r"\.eval_scratch|"
    + re.escape(RUN_MARKER)
    + r"|(model|best_model|checkpoint)(\.zip|_vecnormalize\.pkl)|"
    r"\.(config|command|meta|evaluations|eval_goal|model|best_model|checkpoint)(_vecnormalize)?"
    r"\.[^/]+\.(yml|txt|json|npz|zip|pkl))$"
)  # the last line: atomic writes' temporary files
TB_FILES = re.compile(r"^(ppo|sac|td3)_\d+(/events\.out\.tfevents\.[^/]+)?$")
SCRATCH_FILES = re.compile(r"^evaluations\.npz$")


def _not_a_run(run: Path) -> str:
    """Why ``run`` is not a folder that --overwrite may delete ('' if it is one): a real
    folder (no symlink) that this script created (``RUN_MARKER``), holding only the files it
    writes (``RUN_FILES``; TensorBoard logs under tb/, the evaluation scratch folder), and
    not the working folder, one of its parents or the home folder."""
    here = Path.cwd().resolve()
    if run.is_symlink():
        return "is a symbolic link"
    target = run.resolve()
    if target == here or target in here.parents or target == Path.home().resolve():
        return "is the working folder, one of its parents or the home folder"
    if not run.is_dir():
        return "is not a folder"
    if not (run / RUN_MARKER).is_file():
        return (
            f"has no {RUN_MARKER} marker (only folders this script created can be "
            "replaced; delete an older run folder by hand)"
        )
    other = []
    for p in run.rglob("*"):
        rel = p.relative_to(run)
        top, sub = rel.parts[0], "/".join(rel.parts[1:])
        ok = (
            not p.is_symlink()
            and RUN_FILES.match(top) is not None
            and (
                not sub
                or (top == "tb" and TB_FILES.match(sub) is not None)
                or (top == ".eval_scratch" and SCRATCH_FILES.match(sub) is not None)
            )
        )
        if not ok:
            other.append(str(rel))
    if other:
        return f"holds files a run does not write ({', '.join(sorted(other)[:5])})"
    return ""
