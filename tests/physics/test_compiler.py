"""The kernels' compiler pipeline (``rolling_env.physics._compiler``): LLVM's predicated loop tails
for our kernels only, LLVM's defaults for everything compiled before and after."""

import re

import numpy as np
import pytest
from numba import njit
from numba.core.errors import TypingError

from rolling_env.physics import _compiler

SRC = """
def loop_sum(x, n):
    s = 0.0
    for i in range(n):
        s += x[i] * 2.0 + 1.0
    return s
"""


def _fresh(**opts):
    """A new dispatcher of the same loop (each compiles anew: no dispatcher or cache reuse)."""
    ns = {}
    exec(SRC, ns)
    return njit(cache=False, fastmath={"reassoc"}, **opts)(ns["loop_sum"])


def _asm(fn) -> str:
    x = np.arange(11.0)
    assert fn(x, 11) == pytest.approx(2 * x.sum() + 11, rel=1e-12), "loop compiled wrongly"
    (asm,) = fn.inspect_asm().values()
    return asm


def _code(asm: str) -> list[str]:
    """The instructions of the function itself, without symbol names (numba numbers each
    compiled function differently)."""
    return [
        re.sub(r"_ZN\w+|\.L\w+", "SYM", ln.split("#")[0].strip())
        for ln in asm.splitlines()
        if ln.startswith("\t") and not ln.startswith("\t.")
    ]


def test_options_apply_only_where_known_to_exist_and_help():
    feats = "+avx2,+avx512f,+avx512vl,+fma"
    assert _compiler.options_supported(22, feats, None), "LLVM 22 with AVX-512 on the host"
    assert _compiler.options_supported(11, feats, None), "LLVM 11 has the option's spelling"
    assert not _compiler.options_supported(10, feats, None), "LLVM 10 spelled it otherwise"
    assert not _compiler.options_supported(23, feats, None), "an LLVM not measured yet"
    assert not _compiler.options_supported(22, "+avx2,+fma,-avx512f,-avx512vl", None), (
        "AVX2 only: masked stores are slow on some CPUs"
    )
    assert not _compiler.options_supported(22, feats, "generic"), (
        "numba targets another CPU than the host (NUMBA_CPU_NAME)"
    )


def test_pipeline_changes_our_loops_and_leaves_other_compiles_as_they_were():
    before = _code(_asm(_fresh()))
    ours = _code(_asm(_fresh(pipeline_class=_compiler.Compiler)))
    after = _code(_asm(_fresh()))
    assert after == before, (
        "a numba function compiled after one of our kernels got other machine code: the "
        "LLVM options leaked out of our compile"
    )
    if _compiler.ENABLED:
        assert ours != before, "the pipeline did not change the loop (options not applied)"
        assert any("{%k" in ln for ln in ours), "no masked (predicated) loop tail in our loop"
    else:
        assert ours == before, "options disabled here, yet the pipeline changed the code"


def test_options_restored_when_our_compile_fails():
    before = _code(_asm(_fresh()))

    def bad(x):
        return x.no_such_attribute

    with pytest.raises(TypingError):
        njit(cache=False, pipeline_class=_compiler.Compiler)(bad)(np.zeros(2))
    assert _compiler._depth == 0, "nesting counter left raised after a failed compile"
    assert _code(_asm(_fresh())) == before, "LLVM options left set after a failed compile"


def test_every_kernel_compiles_under_the_pipeline():
    """A kernel decorated without ``pipeline_class`` (e.g. a new one not given ``K.JIT``)
    would silently lose the loop options; ``_compiler`` on the dispatcher is numba's."""
    from rolling_env.env import _envkernel as EK
    from rolling_env.physics import _kernel as K

    kernels = {
        f"{m.__name__}.{n}": v
        for m in (*K.MODULES, EK)
        for n, v in vars(m).items()
        if hasattr(v, "py_func") and v.py_func.__module__ == m.__name__
    }
    assert len(kernels) > 20, f"kernels not found: {sorted(kernels)}"
    other = sorted(
        n
        for n, d in kernels.items()
        if getattr(getattr(d, "_compiler", None), "pipeline_class", None) is not _compiler.Compiler
    )
    assert not other, f"kernels compiled outside rolling_env.physics._compiler.Compiler: {other}"
