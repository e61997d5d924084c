"""Private numba kernels of the finite-volume MDR contact (see ``rolling_env.physics.model`` for the
checked API).

Discretisation
--------------
The 1-D MDR spring row is treated as the continuum it approximates: cell ``i`` covers
``[x_lo + i dx, x_lo + (i+1) dx]`` and stores the tangential *content*
``U_i = integral of uT over (cell intersected with contact)``.  Within a cell the deflection is
taken uniform (``uT = U_i / l_i`` with ``l_i`` the exact overlap of cell and contact).  Over a
sub-step the patch centre ``c`` moves linearly, so the overlap of every cell is piecewise linear
in time; the kernel integrates the creep ODE *exactly* over each linear piece
(``_walk``):

* entry (leading edge inside the cell)   ``dU/dt = s l``               (new material has uT = 0)
* full  (cell inside the contact)        ``dU/dt = s l``
* exit  (trailing edge inside the cell)  ``d(U/l)/dt = s``             (released material
carries the mean)
* both  (contact narrower than a cell)   ``d(U/l)/dt = s - |u| (U/l) / l``

with ``s = omega R - v - v*`` the creep rate.  Because the result is affine in ``s``, each cell
returns ``U_end = A + B s``; the runner equation (backward Euler, implicit in ``v*``) is then
solved exactly for infinite friction and by a safeguarded Newton/bisection on the monotone
piecewise-linear force for finite friction.  Entry and exit times inside a sub-step, partial
cells at both contact edges and the conservative remap when the contact radius jumps are all
exact within the uniform-cell model, which makes the error smooth and second order in ``dx``.

Units are whatever the caller scales to (``model.Drive`` uses length a_ref, time t_ref and
force G* a_ref^2, so ``G* = 1`` here and ``E_over_G = E*/G*``).

Feature specialisation: ``mu``, ``mass`` and ``load`` are ``None`` or float.  numba prunes the
``is None`` branches at compile time, so every scene gets a kernel that contains only what it
needs (no slip checks with infinite friction, no dynamics for a prescribed runner, no load term
without a load); each combination is compiled and cached once.  The energy ledger is a feature
too (``ledger``): without it (the env) an edge cell's content is integrated in closed form
(``_walk_content``) rather than walked piece by piece with the integrals the ledger needs.

Modules, in the order of a tick
-------------------------------
* ``layout``: the compiler options (``JIT``; ``JIT_INLINE`` for the tick's steps, which LLVM
  inlines into the tick) and the layouts of the state vector, the per-tick
  outputs, the cell work array and the params vector, each from one list of names.
* ``cells``: cell index ranges, a cell's overlap, normal content and friction limit, the clip.
* ``grid``: remaps of the contents to another grid level (``_regrid``) and to a new contact
  radius (``_set_radius``).
* ``walk``: the exact creep integration of an edge cell over a sub-step (``_walk``).
* ``runner``: the runner step and the root of the runner equation.
* ``commit``: the inner cells' build loop and the commit of the contents with the slip work.
* ``ledger``: the impulse of a cell that slid, an edge cell's dissipation, the ledger step.
* ``tick``: the tick as a loop of these steps (``_tick``), ``run_ticks`` and two diagnostics.

This package re-exports the names the rest of the code base uses (``from . import _kernel as
K``; ``K._tick``, ``K.ST_C``, ...).  ``SOURCES`` lists its files: numba checks a cached
function against its own file only, so every compiled function here and in ``_envkernel`` is
bound to all of them (``_cachestamp``).
"""

from __future__ import annotations

from pathlib import Path

from .. import _cachestamp, _compiler
from . import cells, commit, grid, layout, ledger, runner, tick, walk
from .cells import (  # noqa: F401
    _contact_range,
    _edge_limit,
    _inner_limit,
    _inner_range,
    _inner_tol,
    _normal_content,
    _overlap,
)
from .commit import _commit  # noqa: F401
from .grid import (  # noqa: F401
    _regrid,
    _set_radius,
    _target_level,
)
from .layout import (  # noqa: F401
    FLAG_GRID,
    FLAG_NONFINITE,
    FLAG_SLIDE,
    JIT,
    L_IA,
    L_IB,
    L_LIMIT,
    L_QLIM,
    L_U0,
    N_LCOL,
    N_OUT,
    N_PARAM,
    N_STATE,
    OUT_C,
    OUT_IMP,
    OUT_N,
    OUT_NAMES,
    OUT_SLIP,
    OUT_STICK,
    OUT_T,
    OUT_VS,
    OUT_XS,
    P_DX,
    P_E_OVER_G,
    P_LEVELS,
    P_R,
    P_X_LO,
    ST_A,
    ST_C,
    ST_D,
    ST_DRIVE,
    ST_EXT,
    ST_FLAG,
    ST_IMP,
    ST_ITER,
    ST_KIN0,
    ST_LEVEL,
    ST_REL,
    ST_RUNNER,
    ST_SLIP,
    ST_SNAP,
    ST_T,
    ST_TIME,
    ST_VS,
    ST_XS,
    ST_XSPH,
    STATE_NAMES,
    W_A,
    W_B,
    W_L,
    W_U,
    work_rows,
)
from .ledger import (  # noqa: F401
    _clip_path,
    _edge_impulse,
    _impulse_fix,
    _limit_integral,
)
from .runner import (  # noqa: F401
    THETA2_BLEND,
    _phis,
    _runner_linear,
)
from .tick import (  # noqa: F401
    _tick,
    elastic_energy,
    normal_force_sum,
    run_ticks,
)
from .walk import (  # noqa: F401
    _inv_speed,
    _walk,
    _walk_content,
)

#: the kernel modules, in the order of a tick
MODULES = (layout, cells, grid, walk, runner, commit, ledger, tick)
#: the package's source files (every module here: a new one is covered without a change)
SOURCES = tuple(sorted(str(f) for f in Path(__file__).parent.glob("*.py")))

_cachestamp.keep_in_step(MODULES, SOURCES + (_compiler.__file__,))
