"""The env kernels' numba cache is dropped when the physics they embed changes."""
from __future__ import annotations

from rolling_env import _envkernel as EK
from rolling_env._cachestamp import drop_if_stale, sources_digest


def test_cache_files_dropped_only_when_sources_change(tmp_path):
    src = tmp_path / "kernel.py"
    src.write_text("x = 1\n")
    cache = tmp_path / "cache"
    cache.mkdir()
    for name in ("_envkernel.f-10.py311.nbi", "_envkernel.f-10.py311.1.nbc",
                 "_kernel.g-5.py311.nbi"):
        (cache / name).write_text("stale")
    d1 = sources_digest(src)
    assert drop_if_stale(cache, "_envkernel", d1), "first sight of the sources must drop"
    left = sorted(p.name for p in cache.iterdir())
    assert left == ["_envkernel.sources.sha1", "_kernel.g-5.py311.nbi"], left
    (cache / "_envkernel.f-10.py311.nbi").write_text("fresh")
    assert not drop_if_stale(cache, "_envkernel", d1), "unchanged sources must keep the cache"
    assert (cache / "_envkernel.f-10.py311.nbi").exists()
    src.write_text("x = 2\n")
    assert drop_if_stale(cache, "_envkernel", sources_digest(src)), "an edit must drop the cache"
    assert not (cache / "_envkernel.f-10.py311.nbi").exists()


def test_env_kernel_stamp_records_the_current_physics():
    """Importing the env kernel left a stamp equal to the digest of _kernel.py + _envkernel.py
    in its cache folder (where numba can write one)."""
    import os
    from pathlib import Path

    import pytest

    from rolling_env import _kernel as K
    cache_dir = getattr(EK.env_step_serial._cache, "cache_path", None)
    if not cache_dir or not os.access(cache_dir, os.W_OK):
        pytest.skip("numba cache folder not writable here")
    stamp = Path(cache_dir) / "_envkernel.sources.sha1"
    assert stamp.exists(), f"no stamp in {cache_dir}"
    assert stamp.read_text() == sources_digest(K.__file__, EK.__file__), "stale stamp"


def test_missing_cache_dir_is_harmless(tmp_path):
    assert not drop_if_stale(None, "_envkernel", "abc")
    assert not drop_if_stale(tmp_path / "nope" / "deeper", "_envkernel", "abc")
