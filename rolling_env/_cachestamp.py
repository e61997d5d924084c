"""Keep numba's on-disk cache of the env kernels in step with the physics they embed.

numba revalidates a cached function against the time stamp of *its own* source file only.  The
env kernels in ``_envkernel.py`` compile ``_kernel.py``'s physics into their machine code, so
after an edit of ``_kernel.py`` (or a ``git pull`` that changes only that file in an editable
install) their cache would keep running the old physics.  ``drop_if_stale`` keeps a digest of
the embedded sources beside the cache and deletes the dependent cache files when it changes.
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path


def sources_digest(*files) -> str:
    h = hashlib.sha1()
    for f in files:
        h.update(Path(f).read_bytes())
    return h.hexdigest()


def drop_if_stale(cache_dir, prefix: str, digest: str) -> bool:
    """Delete ``<prefix>.*.nbi/.nbc`` in ``cache_dir`` unless the stamp there records ``digest``;
    then record it.  Returns True when files were dropped.  Never raises for file-system errors
    (a read-only install simply recompiles or uses numba's fallback cache)."""
    if not cache_dir:
        return False
    cache_dir = Path(cache_dir)
    stamp = cache_dir / f"{prefix}.sources.sha1"
    try:
        if stamp.read_text() == digest:
            return False
    except OSError:
        pass
    dropped = False
    try:
        for f in list(cache_dir.glob(f"{prefix}.*.nbi")) + list(cache_dir.glob(f"{prefix}.*.nbc")):
            f.unlink(missing_ok=True)
            dropped = True
        cache_dir.mkdir(parents=True, exist_ok=True)
        tmp = cache_dir / f"{stamp.name}.{os.getpid()}.tmp"
        tmp.write_text(digest)
        os.replace(tmp, stamp)
    except OSError:
        pass
    return dropped
