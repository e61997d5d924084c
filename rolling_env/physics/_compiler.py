"""numba compiler pipeline of the kernels: LLVM's predicated loop tails, scoped to our compiles.

The cell loops of a sub-step run over 20-40 cells.  LLVM's loop vectoriser by default runs
them 16 cells per iteration (two 8-wide vectors), then a 4-wide epilogue, then a scalar
remainder of up to 3 cells, so most of each loop is its tail, and the tail's trip counts change
from sub-step to sub-step (branches the predictor misses).  With LLVM's options
``-prefer-predicate-over-epilogue=predicate-else-scalar-epilogue`` and
``-force-vector-interleave=1`` a loop runs 8-wide with the last iteration masked (AVX-512
mask registers) and no remainder: the serial batched kernel is about 3% faster on the
default and loaded scenes and 2% on resonant on the project's machine (AMD EPYC Zen 4, 256
envs; docs/performance-log.md, "Compilation options").

These are process-wide LLVM command-line options (llvmlite's ``set_option``; numba has no
per-function switch).  ``Compiler`` sets them only while it compiles one of our kernels and
restores LLVM's defaults afterwards, inside numba's global compiler lock, so no other numba
compilation runs in between: a user's own numba functions compiled before or after are not
affected (tests/physics/test_compiler.py compares their machine code).  Caveats, stated rather than
hidden: numba helpers that our compile triggers for the first time in a process (e.g. the
implementation of a slice assignment) are compiled under the options too and numba reuses
them; the result is equivalent code with masked tails.  An LLVM option the user set to a
non-default value themselves would be reset to LLVM's default by our restore.

Used only where they are known to help and to exist: the host CPU has AVX-512 (masked loads
and stores are cheap; with AVX2 alone masked stores are slow on some CPUs, not measured here),
numba targets the host CPU, and LLVM's major version is one whose option spelling we know
(11-22; measured on LLVM 22).  Anywhere else the kernels compile as numba's default pipeline
does, only slower.
"""

from __future__ import annotations

import contextlib

from numba.core import compiler
from numba.core.compiler_lock import global_compiler_lock

#: (option while our kernels compile, LLVM's default)
LOOP_OPTIONS = (
    (
        "-prefer-predicate-over-epilogue=predicate-else-scalar-epilogue",
        "-prefer-predicate-over-epilogue=scalar-epilogue",
    ),
    ("-force-vector-interleave=1", "-force-vector-interleave=0"),
)
LLVM_MAJOR_KNOWN = (11, 22)

_depth = 0  # nesting of compiles under the options (a kernel's callees compile inside it)


def options_supported(llvm_major: int, cpu_features: str, cpu_name) -> bool:
    """Whether the loop options apply: a known LLVM, AVX-512 on the host, numba targeting it
    (``cpu_name`` None: numba's ``NUMBA_CPU_NAME`` unset)."""
    feats = set(cpu_features.split(","))
    return (
        LLVM_MAJOR_KNOWN[0] <= llvm_major <= LLVM_MAJOR_KNOWN[1]
        and {"+avx512f", "+avx512vl"} <= feats
        and cpu_name is None
    )


def _supported_here() -> bool:
    try:
        import llvmlite.binding as ll
        from numba.core import config

        return options_supported(
            ll.llvm_version_info[0], ll.get_host_cpu_features().flatten(), config.CPU_NAME
        )
    except Exception:  # an llvmlite without these queries: numba's default pipeline
        return False


ENABLED = _supported_here()


@contextlib.contextmanager
def loop_options():
    """LLVM's loop options of ``LOOP_OPTIONS`` set for the duration (outermost use only),
    LLVM's defaults restored after it, all inside numba's global compiler lock; nothing where
    they do not apply (``ENABLED``)."""
    global _depth
    if not ENABLED:
        yield
        return
    import llvmlite.binding as ll

    with global_compiler_lock:
        if _depth == 0:
            for on, _ in LOOP_OPTIONS:
                ll.set_option("", on)
        _depth += 1
        try:
            yield
        finally:
            _depth -= 1
            if _depth == 0:
                for _, off in LOOP_OPTIONS:
                    ll.set_option("", off)


class Compiler(compiler.Compiler):
    """numba's default pipeline, run under ``loop_options`` (``pipeline_class`` of the
    kernels' decorators)."""

    def compile_extra(self, func):
        with loop_options():
            return super().compile_extra(func)

    def compile_ir(self, func_ir, lifted=(), lifted_from=None):
        with loop_options():
            return super().compile_ir(func_ir, lifted, lifted_from)
