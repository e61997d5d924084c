"""Layouts and compiler options shared by the kernel modules: the state vector, the per-tick
outputs, the rows of the cell work array and the params vector, each read from one list of
names, and the flags.

Compiler options (``JIT``, for every kernel here and in ``_envkernel``):

* ``error_model="numpy"``: numba's default ("python") tests every float division for a zero
  divisor so that it can raise ZeroDivisionError (2-3% of an env step).  The divisors here are
  positive by construction; a 0/0 or x/0 would give NaN or inf, which the non-finite flag
  reports.
* ``_nrt=False`` (numba's own switch, private: its tests use it; ``_jit_options``): no
  reference counting.  These kernels allocate nothing; they only index arrays their caller
  owns for the whole call.  With counting on, every call of a non-inlined kernel and every
  per-env view (then ``U[e]``, ``A[e]``, ...; now ``W[e]``) counted its arrays up and down with
  atomic operations, about 45 per env step (measured with the four separate cell arrays of
  before the work array W): 5% of the serial kernel, and in the threaded batch both threads
  contended for the same counters (aggregate +12% without them).  A kernel that allocated
  would fail to compile, not misbehave.  ``env_step_parallel`` keeps counting (prange needs it).
* ``pipeline_class=_compiler.Compiler``: numba's default pipeline, compiled with LLVM's
  predicated loop tails where the CPU has AVX-512 (the cell loops run 8 cells wide with a
  masked last iteration instead of a 16-wide body, a 4-wide epilogue and a scalar remainder:
  2-3% of the env step); the options are set only while our kernels compile (see
  ``_compiler``).
* ``forceinline=False``, set rather than left to numba's default: numba hands a function's
  ``forceinline`` down to the functions it compiles for it that do not set their own, so
  without it the cell loops (``_build_inner``, ``_commit``) and the rare paths that the
  tick's steps call would be inlined too.

``JIT_INLINE``, for the tick's steps and their pieces (``tick._build``, ``runner._runner``,
``commit._commit_cells``, ...): ``JIT`` with ``forceinline=True``.  numba compiles each step
once per signature as a function of its own and marks it ``alwaysinline``, and LLVM inlines
it into the tick: one machine-code body with no call per step, and each step keeps its own
floating-point flags (none, as the tick's).  numba's own ``inline="always"`` instead splices
a function's IR into each caller and compiles it again there, at every level of nesting: for
the steps (which inline the walk, the clip, ...) that doubled the kernel's cold compile time.
The steps are not cached on their own (``cache=False``): the tick's cache entry holds their
inlined code, and the tick is bound to the sources of every kernel file (``_cachestamp``).
Nor do they get the wrappers that let Python call them (``no_cpython_wrapper``,
``no_cfunc_wrapper``): only compiled code calls them.

Three helpers of the edge cells' wear and impulse that ``inline="always"`` spliced in at
several call sites each, nested three levels deep (``ledger._edge_dissipation``,
``_edge_impulse``, ``_limit_integral``), are inlined by LLVM too (``JIT_INLINE_PY`` for the
two that tests call from Python): compiled once per signature, they took most of the compile
time of the commit and ledger steps.  The other small helpers stay ``inline="always"``: LLVM
inlining ``walk._walk`` as well changed the machine code of the infinite-friction tick, which
then measured 4-6% slower in one series of interleaved rounds."""

from __future__ import annotations

from .._compiler import Compiler


def _jit_options() -> dict:
    """``cache``, ``error_model="numpy"``, the pipeline of ``_compiler`` (LLVM's predicated
    loop tails, where they apply), ``forceinline=False`` and, where this numba has it,
    ``_nrt=False`` (see the module docstring).  ``_nrt`` is private: should a numba release
    drop it, the kernels keep reference counting (about 5% slower) rather than fail to compile
    (numba refuses unknown options at the first call); tests/test_kernel_paths.py says so with
    the numba tested."""
    opts = dict(cache=True, error_model="numpy", pipeline_class=Compiler, forceinline=False)
    try:
        from numba.core.cpu import CPUTargetOptions

        if hasattr(CPUTargetOptions, "_nrt"):
            opts["_nrt"] = False
    except Exception:  # numba's internals moved: keep the counting
        pass
    return opts


JIT = _jit_options()
#: the options of the tick's steps (see the module docstring)
JIT_INLINE = dict(
    JIT, forceinline=True, cache=False, no_cpython_wrapper=True, no_cfunc_wrapper=True
)
#: the same for the inlined helpers that tests also call from Python (with the wrappers)
JIT_INLINE_PY = dict(JIT, forceinline=True, cache=False)

#: the per-env state vector, slot by slot; the ST_* indices are read from this one list
STATE_NAMES = (
    "c",  # patch centre c (spring frame)
    "a",  # contact half-width a currently in force
    "d",  # indentation d currently in force
    "vs",  # runner velocity v*
    "xs",  # runner displacement x*
    "xsph",  # sphere translation (integral of v dt)
    "T",  # tangential force T
    "imp",  # cumulative impulse of T
    "slip",  # cumulative slip work (friction dissipation, wear measure)
    "rel",  # cumulative release work (elastic energy carried off by released material)
    "drive",  # cumulative drive work  integral T (omega R - v) dt
    "runner",  # cumulative work of T on the runner  integral T v* dt
    "ext",  # cumulative work of F_ext on the runner
    "time",  # time
    "flag",  # error flags (bit field, see FLAG_*)
    "iter",  # cumulative Newton iterations (finite friction, free runner)
    "snap",  # cumulative elastic energy lost beyond the Coulomb work when springs snap to
    # the lower friction limit of an instantaneous normal-load drop
    "kin0",  # runner's kinetic energy at reset: the ledger's starting balance (written by
    # Drive.reset, read by Drive.energy; the kernel never touches it)
    "level",  # grid level k of a level grid (``P_LEVELS`` > 0): cells of dx / 2^k
)
_ST = {name: i for i, name in enumerate(STATE_NAMES)}
ST_C, ST_A, ST_D, ST_VS, ST_XS = _ST["c"], _ST["a"], _ST["d"], _ST["vs"], _ST["xs"]
ST_XSPH, ST_T, ST_IMP, ST_SLIP, ST_REL = _ST["xsph"], _ST["T"], _ST["imp"], _ST["slip"], _ST["rel"]
ST_DRIVE, ST_RUNNER, ST_EXT, ST_TIME = _ST["drive"], _ST["runner"], _ST["ext"], _ST["time"]
ST_FLAG, ST_ITER, ST_SNAP, ST_KIN0 = _ST["flag"], _ST["iter"], _ST["snap"], _ST["kin0"]
ST_LEVEL = _ST["level"]
N_STATE = len(STATE_NAMES)

FLAG_GRID = 1  # the contact reached the end of the spring row
FLAG_NONFINITE = 2  # a non-finite value appeared (kernel stopped)
FLAG_SLIDE = 4  # massless runner with no force equilibrium (|F_ext| > mu N)

# per-tick outputs, in order; the OUT_* indices are read from this one list
OUT_NAMES = (
    "T",  # T at the end of the tick
    "imp",  # impulse of T over the tick
    "vs",  # v* at the end of the tick
    "xs",  # x* at the end of the tick
    "slip",  # slip work during the tick
    "c",  # patch centre at the end of the tick
    "N",  # normal force
    "stick",  # stuck fraction of the contact length at the end of the tick (1 with mu = inf)
)
_OUT = {name: i for i, name in enumerate(OUT_NAMES)}
OUT_T, OUT_IMP, OUT_VS, OUT_XS = _OUT["T"], _OUT["imp"], _OUT["vs"], _OUT["xs"]
OUT_SLIP, OUT_C, OUT_N, OUT_STICK = _OUT["slip"], _OUT["c"], _OUT["N"], _OUT["stick"]
N_OUT = len(OUT_NAMES)

# rows of the cell work array W (``Drive.cells``, ``BatchCore.cells[e]``; cells along the
# second axis): the tangential contents U, the build pass's A and B (U_end = A + B s), then,
# with finite friction only, the friction work rows L = W[W_L:] (L_* below).  One array
# rather than four separate ones: one argument instead of three for each non-inlined kernel,
# and one env's rows together in memory
W_U, W_A, W_B, W_L = 0, 1, 2, 3

# rows of the friction work array L = W[W_L:]
L_LIMIT = 0  # friction limit mu E*/G* integral of uN over the cell's part in contact
L_QLIM = 1  # an edge cell's friction limit per unit overlap (mu E*/G* times the mean uN
# over its part in contact; 0: none in contact), the mean of its values at
# the sub-step's start and end: the slip work's limit
L_U0, L_IA, L_IB = 2, 3, 4  # of an edge cell, its content at the start of the sub-step and
# its unclipped integral over it, IA + IB s (the wear's trailing-edge term,
# ``_edge_dissipation``, and the ledger's ``_edge_impulse``)
N_LCOL = 5


def work_rows(finite_mu: bool, ledger: bool = True) -> int:
    """Rows of the work array W: U, A, B and, with finite friction, the N_LCOL rows of L (the
    same with the energy ledger and without: ``ledger`` is kept for the callers that say
    which they build)."""
    return W_L + (N_LCOL if finite_mu else 0)


# params vector
P_R = 0
P_E_OVER_G = 1
P_X_LO = 2
P_DX = 3  # cell size at level 0
P_LEVELS = 4  # finest level of the level grid (0: a fixed grid, ``_regrid``)
N_PARAM = 5


# Floating-point sums of the cell loops (the inner cells; in the env's commit every cell of
# the contact) may be reordered (reassoc), which lets LLVM vectorise them (numba leaves the
# SLP vectoriser off, and the loop vectoriser keeps in-order sums scalar): 1.4x per env-step
# on the default scene, and sums that differ from the in-order ones at round-off level
# (relative 1e-15 to 1e-12 on trajectories).  Only these two flags: no
# nnan/ninf (NaN and inf still reach the flag checks), no contract/arcp (the cell-bound tests
# elsewhere rely on exact floating-point comparisons; they are not in these functions, which
# numba compiles separately: inline="always" would drop their fastmath flags).
_FM_INNER = {"reassoc", "nsz"}
