"""The env kernels' numba cache is valid only for the physics they embed
(rolling_env.physics._cachestamp)."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import time
from pathlib import Path
from types import SimpleNamespace

from rolling_env.env import _envkernel as EK
from rolling_env.physics import _compiler
from rolling_env.physics import _kernel as K
from rolling_env.physics._cachestamp import bind_sources, drop_if_stale, sources_digest


def test_env_kernels_are_bound_to_the_current_physics():
    # the compiler options of _compiler shape their machine code too
    digest = sources_digest(*K.SOURCES, EK.__file__, _compiler.__file__)
    for f in (EK.env_step_serial, EK.env_step_parallel, EK._env_tick):
        stamp = f._cache._cache_file._source_stamp
        assert stamp[0] == "rolling_env" and stamp[1][1] == digest, f"{f} not bound: {stamp}"


def test_physics_kernels_are_bound_to_every_kernel_file():
    """A kernel module's compiled functions embed the other modules' inlined steps (the tick
    inlines the walk, the runner step, the commit, ...): each is bound to all of them.  The
    steps LLVM inlines (``K.JIT_INLINE``) are not cached on their own: only in the tick."""
    pkg = Path(K.__file__).parent
    assert set(K.SOURCES) == {str(f) for f in pkg.glob("*.py")}
    assert {m.__file__ for m in K.MODULES} | {K.__file__} == set(K.SOURCES)
    digest = sources_digest(*K.SOURCES, _compiler.__file__)
    bound = 0
    steps = 0
    for m in K.MODULES:
        for f in vars(m).values():
            if hasattr(f, "py_func") and f.py_func.__module__ == m.__name__:
                if f.targetoptions.get("forceinline"):
                    assert type(f._cache).__name__ == "NullCache", f"{f}: a step cached on its own"
                    steps += 1
                    continue
                stamp = f._cache._cache_file._source_stamp
                assert stamp[0] == "rolling_env" and stamp[1][1] == digest, f"{f} not bound"
                bound += 1
    assert bound > 20, bound
    assert steps > 5, steps


def test_bind_sources_is_idempotent_and_reports_missing_internals():
    cf = SimpleNamespace(_source_stamp=("mtime", 12))
    disp = SimpleNamespace(_cache=SimpleNamespace(_cache_file=cf))
    assert bind_sources([disp], "d1")
    assert bind_sources([disp], "d1")
    assert cf._source_stamp == ("rolling_env", (("mtime", 12), "d1")), cf._source_stamp
    assert not bind_sources([SimpleNamespace(_cache=None)], "d1")


_KERNEL = "from numba import njit\n\n@njit(cache=True)\ndef physics(x):\n    return {k} * x\n"
_ENV = textwrap.dedent("""
    import os, sys, time
    from numba import njit
    import kern
    from rolling_env.physics._cachestamp import bind_sources, sources_digest

    @njit(cache=True)
    def step(x):
        return kern.physics(x) + 0.5

    bind_sources([step], sources_digest(kern.__file__, __file__))
    if sys.argv[1] == "wait":  # imported the old physics; compiles only when told to
        open("ready", "w").close()
        while not os.path.exists("go"):
            time.sleep(0.05)
    print(step(1.0))
""")


def test_no_stale_physics_across_processes(tmp_path):
    """A process that imported the old kernel and compiles after the kernel file changed (and
    after a process with the new kernel cached its result) must not leave old physics in the
    cache for later processes."""
    (tmp_path / "kern.py").write_text(_KERNEL.format(k=1.0))
    (tmp_path / "envk.py").write_text(_ENV)

    def run(*args, wait=True):
        cmd = [sys.executable, "envk.py", *args]
        if not wait:
            return subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, text=True)
        return subprocess.run(
            cmd, cwd=tmp_path, capture_output=True, text=True, check=True
        ).stdout.strip()

    assert run("now") == "1.5"  # old physics cached
    old = run("wait", wait=False)  # imports the old physics, then waits
    t0 = time.time()
    while not (tmp_path / "ready").exists():
        assert time.time() - t0 < 60, "old process did not start"
        time.sleep(0.05)
    time.sleep(1.1)  # a new mtime even on coarse file systems
    (tmp_path / "kern.py").write_text(_KERNEL.format(k=3.0))
    assert run("now") == "3.5", "the new physics must not load the old cache"
    (tmp_path / "go").touch()
    assert old.communicate(timeout=60)[0].strip() == "1.5"  # it still runs what it imported
    assert run("now") == "3.5", "a process with old physics left its result in the cache"


def test_fallback_drops_cache_files_only_when_sources_change(tmp_path):
    src = tmp_path / "kernel.py"
    src.write_text("x = 1\n")
    cache = tmp_path / "cache"
    cache.mkdir()
    for name in (
        "_envkernel.f-10.py311.nbi",
        "_envkernel.f-10.py311.1.nbc",
        "_kernel.g-5.py311.nbi",
    ):
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
    assert not drop_if_stale(None, "_envkernel", "abc")
