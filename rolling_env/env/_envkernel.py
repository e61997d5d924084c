"""Private numba kernel of one control tick of RollingDrive-v0 for a batch of envs.

Action mapping, stroke saturation, the physics tick (``_kernel.tick._tick``), observation and
reward in one compiled call.  The single env runs it with a batch of one, the vector envs with
N, so both give bit-identical transitions by construction.  Scene constants travel in ``sv``
(indices ``S_*``); everything is SI outside ``_tick``.
"""

from __future__ import annotations

import math
import sys

import numpy as np
from numba import njit, prange

from rolling_env.physics import _compiler
from rolling_env.physics import _kernel as K

# scene vector
S_N_MIN, S_N_MAX, S_UMAX, S_CREEP, S_STROKE_R, S_STROKE_T, S_R, S_E = range(8)
S_DT, S_L0, S_T0, S_F0, S_W0, S_TMAX, S_VREF, S_TREF, S_WREF = range(8, 17)
S_WTRACK, S_WWEAR, S_TPP, S_EPISODE, S_NSUB = range(17, 22)
# derived constants (the tick multiplies by them instead of dividing per tick)
S_HERTZ, S_TS, S_DTSUB, S_INV_L0, S_INV_TMAX, S_INV_VREF, S_INV_SR, S_INV_ST = range(22, 30)
S_INV_NMAX, S_INV_TREF, S_INV_EPISODE, S_INV_WREF = range(30, 34)
S_WFINAL, S_INV_TOL = range(34, 36)  # terminal term: weight and 1 / tolerance
N_SV = 36
# followed by the observation clock: sin and cos of 2 pi j / ticks_per_period at
# sv[N_SV + 2 j] and sv[N_SV + 2 j + 1], j = 0 .. ticks_per_period - 1 (a table: the clock
# repeats every period, and two transcendental calls per tick were 3% of the default step)

# per-env extras written besides the observation, in order: the reward, then the info values
# under their info keys (``env.INFO_COLUMNS`` is this list less the reward); the X_* indices
# are read from it
EXTRA_NAMES = (
    "reward",
    "reward_track",
    "reward_wear",
    "reward_final",
    "saturation",
    "omega_R",
    "v",
    "N",
    "T",
    "slip_work",
    "stick_fraction",
    "xstar",
    "vstar",
)
_X = {name: i for i, name in enumerate(EXTRA_NAMES)}
X_REWARD, X_TRACK, X_WEAR, X_FINAL = (_X[k] for k in EXTRA_NAMES[:4])
X_SAT, X_U, X_V, X_N, X_T = _X["saturation"], _X["omega_R"], _X["v"], _X["N"], _X["T"]
X_SLIP, X_STICK, X_XS, X_VS = _X["slip_work"], _X["stick_fraction"], _X["xstar"], _X["vstar"]
N_X = len(EXTRA_NAMES)

# the observation, in order (``RollingDriveEnv.observation_space``); the O_* indices are read
# from this one list
OBS_NAMES = (
    "error",
    "vstar",
    "roll_pos",
    "translate_pos",
    "normal_force",
    "tangential_force",
    "stick_fraction",
    "clock_sin",
    "clock_cos",
    "time_fraction",
    "last_N",
    "last_roll",
    "last_creep",
)
_O = {name: i for i, name in enumerate(OBS_NAMES)}
O_ERROR, O_VSTAR, O_ROLL, O_TRANSLATE = (_O[k] for k in OBS_NAMES[:4])
O_N, O_T, O_STICK = _O["normal_force"], _O["tangential_force"], _O["stick_fraction"]
O_SIN, O_COS, O_TIME = _O["clock_sin"], _O["clock_cos"], _O["time_fraction"]
O_LAST_N, O_LAST_ROLL, O_LAST_CREEP = _O["last_N"], _O["last_roll"], _O["last_creep"]
N_OBS = len(OBS_NAMES)
OBS_BOUND = 10.0


@njit(inline="always", **K.JIT)
def _travel(pos, step, limit):
    new = pos + step
    if abs(new) <= limit or step == 0.0:
        return 1.0
    room = (math.copysign(limit, step) - pos) / step
    if room > 1e-12:
        return min(max(room, 0.0), 1.0)
    return 0.0


@njit(inline="always", **K.JIT)
def _clip(x):
    return min(max(x, -OBS_BOUND), OBS_BOUND)


@njit(**K.JIT)
def _env_tick(e, act, sv, target, steps, W, st, p, out, obs, extra, mu, mass, load, ledger):
    a0 = min(max(act[e, 0], -1.0), 1.0)
    a1 = min(max(act[e, 1], -1.0), 1.0)
    a2 = min(max(act[e, 2], -1.0), 1.0)
    N = sv[S_N_MIN] + 0.5 * (a0 + 1.0) * (sv[S_N_MAX] - sv[S_N_MIN])
    u = a1 * sv[S_UMAX]
    v = u * (1.0 - a2 * sv[S_CREEP])
    dt = sv[S_DT]
    L0 = sv[S_L0]
    t0 = sv[S_T0]
    ste = st[e]
    f = min(
        _travel(ste[K.ST_C] * L0, u * dt, sv[S_STROKE_R]),
        _travel(ste[K.ST_XSPH] * L0, v * dt, sv[S_STROKE_T]),
    )
    u *= f
    v *= f
    cb = np.cbrt(N * sv[S_HERTZ])  # Hertz: d = cb^2
    d = cb * cb
    ts = sv[S_TS]
    K._tick(
        W[e],
        ste,
        p[e],
        d * sv[S_INV_L0],
        u * ts,
        v * ts,
        0.0,
        mu,
        mass,
        load,
        int(sv[S_NSUB]),
        sv[S_DTSUB],
        out[e],
        ledger,
    )
    steps[e] += 1
    oe = out[e]
    xs = ste[K.ST_XS] * L0
    vs = ste[K.ST_VS] * L0 / t0
    Nn = oe[K.OUT_N] * sv[S_F0]
    T = oe[K.OUT_T] * sv[S_F0]
    slip = oe[K.OUT_SLIP] * sv[S_W0]
    err = target[e] - xs
    k = steps[e]
    j = N_SV + 2 * (k % int(sv[S_TPP]))
    ob = obs[e]
    ob[O_ERROR] = _clip(err * sv[S_INV_TMAX])
    ob[O_VSTAR] = _clip(vs * sv[S_INV_VREF])
    ob[O_ROLL] = _clip(ste[K.ST_C] * L0 * sv[S_INV_SR])
    ob[O_TRANSLATE] = _clip(ste[K.ST_XSPH] * L0 * sv[S_INV_ST])
    ob[O_N] = _clip(Nn * sv[S_INV_NMAX])
    ob[O_T] = _clip(T * sv[S_INV_TREF])
    ob[O_STICK] = oe[K.OUT_STICK]
    ob[O_SIN] = sv[j]
    ob[O_COS] = sv[j + 1]
    ob[O_TIME] = _clip(k * sv[S_INV_EPISODE])
    ob[O_LAST_N] = a0
    ob[O_LAST_ROLL] = a1
    ob[O_LAST_CREEP] = a2
    track = -sv[S_WTRACK] * abs(err) * sv[S_INV_TMAX]
    wear = -sv[S_WWEAR] * slip * sv[S_INV_WREF]
    final = 0.0
    if k == int(sv[S_EPISODE]):  # the episode's last tick: the final error, in tolerances
        final = -sv[S_WFINAL] * abs(err) * sv[S_INV_TOL]
    x = extra[e]
    x[X_REWARD] = track + wear + final
    x[X_TRACK] = track
    x[X_WEAR] = wear
    x[X_FINAL] = final
    x[X_SAT] = f
    x[X_U] = u
    x[X_V] = v
    x[X_N] = Nn
    x[X_T] = T
    x[X_SLIP] = slip
    x[X_STICK] = oe[K.OUT_STICK]
    x[X_XS] = xs
    x[X_VS] = vs


@njit(**K.JIT)
def _actions_valid(act):
    """Every action finite and inside [-1, 1] (1e-6 tolerance; within it the tick clips)."""
    for e in range(act.shape[0]):
        for j in range(3):
            x = act[e, j]
            if not (abs(x) <= 1.0 + 1e-6):  # also False for NaN
                return False
    return True


@njit(inline="always", **K.JIT)
def _env_bad(e, st, extra):
    """1 when env e raised a grid or non-finite flag or has a non-finite reward or velocity."""
    flag = int(st[e, K.ST_FLAG]) & (K.FLAG_GRID | K.FLAG_NONFINITE)
    ok = math.isfinite(extra[e, X_REWARD]) and math.isfinite(extra[e, X_VS])
    return 1 if (flag != 0 or not ok) else 0


@njit(**K.JIT)
def mark_failed(st, extra, failed):
    """``failed[e]`` = 1 for each env ``_env_bad`` counts, else 0 (for the step error's
    message; not on the hot path)."""
    for e in range(st.shape[0]):
        failed[e] = _env_bad(e, st, extra)


@njit(inline="always", **K.JIT)
def _env_outputs(e, steps, extra, limit, rew, trunc):
    """Env e's reward and truncation flag (its step count reached ``limit``) into the
    contiguous ``rew`` and ``trunc``, which the batched step returns: read by the calling
    thread, they span 36 cache lines for 256 envs where the reward column of ``extra`` and the
    step counts span 288, which the thread that stepped the env must then hand over."""
    rew[e] = extra[e, X_REWARD]
    trunc[e] = steps[e] >= limit


@njit(**K.JIT)
def env_step_serial(
    act, sv, target, steps, W, st, p, out, obs, extra, rew, trunc, limit, mu, mass, load, ledger
):
    """Step every env one tick.  Returns -1 (nothing stepped) when an action is out of range or
    not finite, else the number of envs left with an error (see ``_env_bad``).  Writes each
    env's reward to ``rew`` (float64) and ``steps >= limit`` to ``trunc`` (bool)."""
    if not _actions_valid(act):
        return -1
    bad = 0
    for e in range(act.shape[0]):
        _env_tick(e, act, sv, target, steps, W, st, p, out, obs, extra, mu, mass, load, ledger)
        _env_outputs(e, steps, extra, limit, rew, trunc)
        bad += _env_bad(e, st, extra)
    return bad


@njit(
    cache=True,
    parallel=True,
    error_model="numpy",  # NRT on: prange needs it
    pipeline_class=_compiler.Compiler,
)
def env_step_parallel(
    act, sv, target, steps, W, st, p, out, obs, extra, rew, trunc, limit, mu, mass, load, ledger
):
    """``env_step_serial`` with the envs spread over threads (prange)."""
    if not _actions_valid(act):
        return -1
    bad = 0
    for e in prange(act.shape[0]):
        _env_tick(e, act, sv, target, steps, W, st, p, out, obs, extra, mu, mass, load, ledger)
        _env_outputs(e, steps, extra, limit, rew, trunc)
        bad += _env_bad(e, st, extra)
    return bad


@njit(**K.JIT)
def reset_obs(e, sv, target, obs):
    """Observation right after a reset (runner at rest, no contact, step 0)."""
    ob = obs[e]
    for i in range(N_OBS):
        ob[i] = 0.0
    ob[O_ERROR] = _clip(target[e] * sv[S_INV_TMAX])  # as in _env_tick
    ob[O_COS] = 1.0  # cos(0)


def scene_vector(scene, a_max: float, drive, scales=None) -> np.ndarray:
    """Scene constants for the kernel (see ``S_*``); the observation and reward scales
    (``T_ref``, ``wear_ref``) from ``scales`` where given (a randomised scene's nominal
    values: the same in every episode), else from ``scene``."""
    sc = scene
    ns = scales if scales is not None else scene
    v_ref = 0.3 * sc.creep_max * sc.omega_R_max
    T_stuck = 2 * a_max * sc.G_star * sc.creep_max * sc.stroke_roll
    T_ref = min(ns.mu * sc.N_max, T_stuck)
    wear_ref = (
        ns.mu * sc.N_max * sc.creep_max * sc.omega_R_max * sc.dt if math.isfinite(ns.mu) else 1.0
    )
    tpp = sc.ticks_per_period
    sv = np.zeros(N_SV + 2 * tpp)
    phase = 2.0 * np.pi * np.arange(tpp) / tpp
    sv[N_SV::2] = np.sin(phase)
    sv[N_SV + 1 :: 2] = np.cos(phase)
    sv[[S_N_MIN, S_N_MAX, S_UMAX, S_CREEP, S_STROKE_R, S_STROKE_T, S_R, S_E]] = (
        sc.N_min,
        sc.N_max,
        sc.omega_R_max,
        sc.creep_max,
        sc.stroke_roll,
        sc.stroke_translate,
        sc.R,
        sc.E_star,
    )
    sv[[S_DT, S_L0, S_T0, S_F0, S_W0, S_TMAX, S_VREF, S_TREF, S_WREF]] = (
        sc.dt,
        drive.L0,
        drive.t0,
        drive.F0,
        drive.W0,
        sc.target_max,
        v_ref,
        T_ref,
        wear_ref,
    )
    sv[[S_WTRACK, S_WWEAR, S_TPP, S_EPISODE, S_NSUB]] = (
        sc.w_track,
        sc.w_wear,
        tpp,
        sc.episode_steps,
        sc.n_sub,
    )
    sv[[S_HERTZ, S_TS, S_DTSUB]] = (
        3.0 / (4.0 * sc.E_star * math.sqrt(sc.R)),
        drive.t0 / drive.L0,
        sc.dt / sc.n_sub / drive.t0,
    )
    sv[S_INV_L0:S_WFINAL] = (
        1.0 / sv[[S_L0, S_TMAX, S_VREF, S_STROKE_R, S_STROKE_T, S_N_MAX, S_TREF, S_EPISODE, S_WREF]]
    )
    sv[[S_WFINAL, S_INV_TOL]] = sc.w_final, 1.0 / sc.tolerance
    return sv


def _keep_cache_in_step():
    """The cache of these kernels is valid only for the current physics kernel (every file of
    ``_kernel``), this file and _compiler.py (see _cachestamp)."""
    from rolling_env.physics._cachestamp import keep_in_step

    keep_in_step([sys.modules[__name__]], K.SOURCES + (__file__, _compiler.__file__))


_keep_cache_in_step()
