"""Keep numba's on-disk cache of the env kernels in step with the physics they embed.

numba revalidates a cached function against a stamp of *its own* source file only, taken when
the function is defined.  The env kernels in ``_envkernel.py`` compile the physics of the
``_kernel`` package into their machine code, and the tick in ``_kernel/tick.py`` inlines the
steps of the other kernel modules, so after an edit of one of them (or a ``git pull`` that
changes only that file in an editable install) their cache would keep running the old physics.

``bind_sources`` extends the stamp each env-kernel dispatcher checks and writes with a digest
of every file it embeds.  Like numba's own stamp it is taken at import, per process, so a
process that imported the old physics writes its cache entries under the old digest, and a
process with the new physics ignores them (no race between processes).  If a numba version
lacks the internals this relies on, ``drop_if_stale`` is the fallback: it deletes the
dependent cache files when a digest stored beside them changed (not race-free).
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


def bind_sources(dispatchers, digest: str) -> bool:
    """Make each dispatcher's cache index valid only for ``digest`` (numba's own source stamp
    plus the digest).  Returns False when numba's cache internals are not as expected."""
    files = []
    for d in dispatchers:
        cf = getattr(getattr(d, "_cache", None), "_cache_file", None)
        if cf is None or not hasattr(cf, "_source_stamp"):
            return False
        files.append(cf)
    for cf in files:
        base = cf._source_stamp
        if not (isinstance(base, tuple) and len(base) == 2 and base[0] == "rolling_env"):
            cf._source_stamp = ("rolling_env", (base, digest))
    return True


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


def keep_in_step(modules, files) -> None:
    """Bind every compiled function that ``modules`` define to the digest of ``files``
    (``bind_sources``); where numba's internals differ, drop each module's cache files when
    the digest changed (``drop_if_stale``)."""
    digest = sources_digest(*files)
    for m in modules:
        kernels = [
            f
            for f in vars(m).values()
            if hasattr(f, "_cache")
            and type(f._cache).__name__ != "NullCache"  # not cached (cache=False)
            and hasattr(f, "py_func")
            and getattr(f.py_func, "__module__", None) == m.__name__
        ]
        if kernels and not bind_sources(kernels, digest):
            cache_dir = getattr(kernels[0]._cache, "cache_path", None)
            drop_if_stale(cache_dir, m.__name__.rsplit(".", 1)[-1], digest)
