"""The paper's numerical experiments as pure functions (used by the CLI, tests and scripts).

* ``working_point``: quasi-static working point v*/(omega R) from the zero-impulse condition
  (Eq. 31), infinite friction and runner mass.
* ``simulate``: the same square wave driving a runner of finite mass (and friction).
* ``force_sum`` / ``impulse``: the steady force sum and the period impulse (paper Figs. 6, 8).

Dimensionless inputs follow the paper; the SI geometry only matters with finite friction
(a1/R and G*/E*) and is fixed by ``Geometry``.
"""

from __future__ import annotations

import math
import numbers
import time
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq

from rolling_env.physics import analytic
from rolling_env.physics.excitation import SquareWave
from rolling_env.physics.model import Drive, DriveParams, check_n_sub
from rolling_env.physics.ranges import PHYSICAL_RANGES
from rolling_env.validation import check_int, check_range

DEFAULT_RESOLUTION = (
    64.0  # springs per a1; chosen from results/work_precision.csv (docs/numerical-quality.md)
)


A_OVER_R_RANGE = (1e-6, 0.5)


@dataclass(frozen=True)
class Geometry:
    """SI geometry behind the dimensionless runs: sphere radius R [m], E* [Pa],
    a1/R (``a_over_r``) and G*/E* (``g_over_e``), period tau [s]."""

    R: float = 1e-3
    E_star: float = 115e9
    a_over_r: float = 0.02
    g_over_e: float = 2 * (1 - 0.3) / (2 - 0.3)
    tau: float = 1e-3

    def __post_init__(self):
        # the scenes' physical ranges for R, E* and the period; a1/R from 1e-6 (below, the
        # energy unit 2 G* a1^3 underflows for small spheres) to 0.5 (small-strain contact)
        for name, key in (("R", "R"), ("E_star", "E_star"), ("tau", "period")):
            _, lo, hi, _, _ = PHYSICAL_RANGES[key]
            check_range(name, getattr(self, name), lo, hi)
        check_range("a_over_r", self.a_over_r, A_OVER_R_RANGE[0], A_OVER_R_RANGE[1])
        check_range("g_over_e", self.g_over_e, 0.0, 10.0, lo_open=True)

    @property
    def a1(self) -> float:
        return self.a_over_r * self.R

    @property
    def G_star(self) -> float:
        return self.g_over_e * self.E_star


def _drive(
    wave: SquareWave,
    geo: Geometry,
    params: DriveParams,
    resolution: float,
    grid_offset: float = 0.0,
) -> Drive:
    return Drive(
        params,
        a_ref=wave.a1,
        resolution=resolution,
        stroke=wave.stroke,
        a_max=wave.a1,
        t_ref=wave.tau,
        grid_offset=grid_offset,
    )


MAX_TICKS = 5 * 10**6  # ticks of one simulated run: its per-tick inputs and outputs are held
# in memory, measured at 225 B a tick at the peak (simulate of 2e6 ticks: 636 MB resident,
# 182 MB for 4 ticks), so a run at the cap needs about 1.3 GB (the old cap of 2e7: 4.5 GB)
TICKS_PER_HALF_MAX = 10**5


def _check_common(delta, eps, w, resolution):
    """(delta, eps, w, resolution) checked, the first three as floats (a numeric string
    passed the check and then failed inside the arithmetic); resolution as given when it is a
    number (results report it as passed)."""
    # delta = 0 (no back-step contact) is physical: Eq. 32 gives v* = (1 - eps) omega R there
    delta = check_range("delta", delta, 0.0, 1.0)
    eps = check_range("eps", eps, -1e3, 1e3)
    w = check_range("w", w, 0.0, 1e4, lo_open=True)
    res = check_range("resolution", resolution, 2.0, 1e5)
    return delta, eps, w, (resolution if isinstance(resolution, numbers.Real) else res)


def _check_run_length(periods, ticks_per_half, lo=1):
    """``periods`` an integer >= lo and ``ticks_per_half`` an integer in [1,
    TICKS_PER_HALF_MAX], with at most MAX_TICKS ticks in all; returns both as ints."""
    ticks_per_half = check_int("ticks_per_half", ticks_per_half, 1, TICKS_PER_HALF_MAX)
    periods = check_int("periods", periods, lo, MAX_TICKS // 2)
    ticks = 2 * periods * ticks_per_half
    if ticks > MAX_TICKS:
        raise ValueError(
            f"periods x 2 ticks_per_half = {ticks} ticks exceeds {MAX_TICKS:.0e} "
            "(one run keeps every tick's inputs and outputs in memory): lower "
            "periods or ticks_per_half"
        )
    return periods, ticks_per_half


def _impulse_run(delta, eps, w, vstar_ratio, resolution, geo, ticks_per_half, n_sub, grid_offset):
    """A prescribed-runner drive under the square wave: returns ``run(k)``, which runs k more
    periods in one kernel call and gives the impulse of T of each, normalised as
    I / (2 G* a1^2 tau)."""
    wave = SquareWave(delta, eps, w, geo.a1, geo.R, geo.tau)
    drv = _drive(wave, geo, DriveParams(geo.R, geo.E_star, geo.G_star), resolution, grid_offset)
    drv.reset()
    dt = wave.dt_tick(ticks_per_half)
    vs = vstar_ratio * wave.omega_R
    unit = 2 * geo.G_star * wave.a1**2 * wave.tau
    per = 2 * ticks_per_half

    def run(k):
        d, u, v = wave.ticks(k, ticks_per_half)
        out = drv.run(dt_tick=dt, n_sub=n_sub, omega_R=u, v=v, d=d, vstar=vs)
        return out["impulse"].reshape(k, per).sum(axis=1) / unit

    return run


def period_impulse(
    delta,
    eps,
    w,
    vstar_ratio,
    *,
    resolution=DEFAULT_RESOLUTION,
    periods=3,
    geo: Geometry = Geometry(),
    ticks_per_half=1,
    n_sub=1,
    grid_offset=0.0,
):
    """Impulse of T over the last of ``periods`` periods with a prescribed runner
    (infinite friction), normalised as I / (2 G* a1^2 tau) (paper Fig. 8)."""
    delta, eps, w, resolution = _check_common(delta, eps, w, resolution)
    vstar_ratio = check_range("vstar_ratio", vstar_ratio, -1e3, 1e3)
    periods, ticks_per_half = _check_run_length(periods, ticks_per_half)
    run = _impulse_run(
        delta, eps, w, vstar_ratio, resolution, geo, ticks_per_half, n_sub, grid_offset
    )
    return float(run(periods)[-1])


STEADY_TOL = 1e-12  # periodic steady state: the working point changes less than this per
STEADY_MAX_PERIODS = 2000  # period (in omega R), checked from ``periods`` on, up to this many


def working_point(
    delta,
    eps,
    w,
    *,
    resolution=DEFAULT_RESOLUTION,
    periods=3,
    geo: Geometry = Geometry(),
    grid_offset=0.0,
    until_steady=True,
):
    """Simulated working point v*/(omega R): the zero of the period impulse (Eq. 31).

    With infinite friction and a prescribed runner the impulse is affine in v*, so two runs
    give the zero exactly.  Both run ``periods`` periods, then (``until_steady``) on period by
    period until the working point of the last period differs from the one before by less
    than ``STEADY_TOL`` (at most ``STEADY_MAX_PERIODS``; for w >= 2 the state is periodic
    after the first period unless w - 2 and 1 - sqrt(delta) are both below a cell, where the
    start-up transient decays over up to ~20 periods; below w = 1 + sqrt(delta), where some
    springs never release, the state can become periodic or not at all).  ``until_steady=False``
    runs exactly ``periods`` periods.
    Returns a dict with ``simulated``, ``eq32`` (None for w < 2), ``eq29``, ``rel_error``,
    ``periods`` (run), ``steady`` and ``seconds``, and a ``note`` where the run ended without
    a steady state or where 1 - sqrt(delta) is smaller than two cells (not resolved: relative
    errors of 1-10% were measured there, several times Eq. 32 when w - 2 is below two cells
    too)."""
    delta, eps, w, resolution = _check_common(delta, eps, w, resolution)
    periods = check_int("periods", periods, 2, STEADY_MAX_PERIODS)
    t0 = time.perf_counter()
    runs = [_impulse_run(delta, eps, w, V, resolution, geo, 1, 1, grid_offset) for V in (0.0, 0.1)]
    sims, k, steady = _periods_until_steady(runs, periods, until_steady)
    sim, prev = float(sims[-1]), float(sims[-2])
    seconds = time.perf_counter() - t0
    eq32 = float(analytic.eq32(delta, eps, w)) if w >= 2 else None
    res = {
        "simulated": float(sim),
        "eq32": eq32,
        "eq29": float(analytic.eq29(delta, eps)),
        "rel_error": (float(abs(sim - eq32) / abs(eq32)) if eq32 not in (None, 0.0) else None),
        "seconds": seconds,
        "delta": delta,
        "eps": eps,
        "w": w,
        "resolution": resolution,
        "periods": k,
        "steady": bool(steady),
    }
    notes = []
    if not steady:
        notes.append(
            f"not periodic after {k} periods: the value is the last period's and "
            f"still changed by {abs(sim - prev):.1e} in it"
            + ("" if until_steady else " (until_steady=False)")
        )
    notes += _resolution_notes(delta, w, resolution, eq32 is not None)
    if w < 2:
        notes.append("Eq. 32 holds for w >= 2 only: no eq32 value here")
        try:
            res["working_point_ratio"] = float(analytic.working_point_ratio(delta, eps, w))
        except ValueError as e:
            res["working_point_ratio"] = None
            notes.append(str(e))
    if notes:
        res["note"] = "; ".join(notes)
    return res


def _periods_until_steady(runs, periods: int, until_steady: bool):
    """The working point of each period so far of the two prescribed-runner ``runs`` (v* = 0
    and 0.1 omega R), after ``periods`` periods and (``until_steady``) on until a period's
    repeats the one before; returns them, the periods run and whether that was reached."""
    i0, i1 = runs[0](periods), runs[1](periods)
    sims = -0.1 * i0 / (i1 - i0)  # the working point of each period so far
    k = periods
    steady = abs(sims[-1] - sims[-2]) <= STEADY_TOL
    chunk = 8
    while until_steady and not steady and k < STEADY_MAX_PERIODS:
        # further periods in growing chunks (one kernel call each), stopping at the first
        # period whose working point repeats the one before
        c = min(chunk, STEADY_MAX_PERIODS - k)
        j0, j1 = runs[0](c), runs[1](c)
        more = np.concatenate([sims[-1:], -0.1 * j0 / (j1 - j0)])
        hit = np.flatnonzero(np.abs(np.diff(more)) <= STEADY_TOL)
        if hit.size:
            sims = np.concatenate([sims, more[1 : hit[0] + 2]])
            k += hit[0] + 1
            steady = True
        else:
            sims = np.concatenate([sims, more[1:]])
            k += c
        chunk = min(2 * chunk, 256)
    return sims, k, steady


def _resolution_notes(delta, w, resolution, has_eq32: bool) -> list:
    """A note where the back-step contact edge, 1 - sqrt(delta) a1 from the forth step's,
    spans under two cells (not resolved), else none."""
    gap = 1.0 - math.sqrt(delta)  # a1 - a2 in a1: the back-step contact edge
    if not 0.0 < gap < 2.0 / resolution:
        return []
    need = math.ceil(8.0 / gap)
    both = has_eq32 and w - 2.0 < 2.0 / resolution
    return [
        f"1 - sqrt(delta) = {gap:.3g} a1 spans {gap * resolution:.2g} cells: not "
        "resolved, the relative error can reach "
        + (
            "several times Eq. 32 (w - 2 is below two cells too)"
            if both
            else "1% at 64 and 10% at 16 cells per a1"
        )
        + (
            f"; about {need} cells per a1 resolve it"
            if need <= 1e5
            else "; it cannot be resolved within the largest resolution (1e5)"
        )
    ]


def force_sum(
    delta,
    eps,
    w,
    vstar_ratio,
    *,
    resolution=DEFAULT_RESOLUTION,
    periods=2,
    geo: Geometry = Geometry(),
    ticks_per_half=8,
):
    """Steady rolling force sum (T1 + T2)/(2 G* a1^2) (paper Fig. 6): T at the end of the last
    forth and back steps with a prescribed runner (steady for w >= 2)."""
    delta, eps, w, resolution = _check_common(delta, eps, w, resolution)
    vstar_ratio = check_range("vstar_ratio", vstar_ratio, -1e3, 1e3)
    periods, ticks_per_half = _check_run_length(periods, ticks_per_half)
    wave = SquareWave(delta, eps, w, geo.a1, geo.R, geo.tau)
    drv = _drive(wave, geo, DriveParams(geo.R, geo.E_star, geo.G_star), resolution)
    drv.reset()
    d, u, v = wave.ticks(periods, ticks_per_half)
    out = drv.run(
        dt_tick=wave.dt_tick(ticks_per_half),
        n_sub=1,
        omega_R=u,
        v=v,
        d=d,
        vstar=vstar_ratio * wave.omega_R,
    )
    T = out["T"]
    T1 = T[-ticks_per_half - 1]
    T2 = T[-1]
    return (T1 + T2) / (2 * geo.G_star * wave.a1**2)


ENERGY_FLOOR = 1e-9  # round-off floor of energy balances, in 2 G* a1^3 per period
OMEGA_N_RATIO_RANGE = (1e-100, 1e100)  # finite nonzero r: m stays a finite positive double


def check_omega_n_ratio(r, name: str = "omega_n_ratio") -> float:
    """omega_n / Omega: 0 (infinitely heavy runner), inf (massless) or a finite value inside
    ``OMEGA_N_RATIO_RANGE``; anything else raises one ValueError naming all three."""
    lo, hi = OMEGA_N_RATIO_RANGE
    allowed = f"0 (infinitely heavy runner), inf (massless) or in [{lo:g}, {hi:g}]"
    x = check_range(name, r, 0.0, math.inf, allow_inf=True, allowed=allowed)
    if x != 0.0 and math.isfinite(x) and not lo <= x <= hi:
        raise ValueError(f"{name} must be {allowed}, got {x!r}")
    return x


def natural_frequency_mass(r: float, wave: SquareWave, G_star: float) -> float:
    """Runner mass m [kg] for omega_n / Omega = r with omega_n = sqrt(2 a1 G*/m), Omega = 2
    pi/tau."""
    r = check_omega_n_ratio(r)
    if r == 0:
        return math.inf
    if math.isinf(r):
        return 0.0
    Omega = 2 * math.pi / wave.tau
    return 2 * wave.a1 * G_star / (r * Omega) ** 2


def simulate(
    delta,
    eps,
    w,
    omega_n_ratio,
    *,
    mu=math.inf,
    periods=40,
    resolution=DEFAULT_RESOLUTION,
    geo: Geometry = Geometry(),
    ticks_per_half=1,
    n_sub=None,
    direction=1,
    F_ext=0.0,
    vstar0_ratio=0.0,
    record=False,
):
    """Square-wave excitation driving a free runner of mass m (omega_n/Omega = r).

    r = omega_n / Omega with omega_n = sqrt(2 a1 G*/m) and Omega = 2 pi / tau; r = inf is a
    massless runner (force equilibrium), r = 0 an infinitely heavy one: it moves at the
    constant velocity whose period impulse vanishes (the steady state every heavy runner
    relaxes to), found by root finding on the simulated impulse.  ``vstar0_ratio`` is the
    runner's initial v*/(omega R).

    ``F_ext`` [N] is the load on the runner in the absolute frame (positive along +x, as in
    ``DriveParams``): ``direction`` = -1 mirrors the excitation, not the load, so a load that
    opposes the mirrored drive is positive.  With a massless runner (omega_n_ratio = inf) the
    load must stay within what the contact holds (|F_ext| <= mu N at the back-step force too),
    else the run raises ValueError (no force equilibrium).

    Sub-steps: ``n_sub`` per tick, by default ``default_substeps`` (the mean velocity within
    1% of its converged value, or 1e-3 x Eq. 32 where it is near zero, up to omega_n/Omega =
    100; with finite friction the slip work within 0.5%: the patch moves 1/8 cell per
    sub-step).  A coarser ``n_sub`` converges at second order: fewer than 64 sub-steps per
    runner period 2 pi/omega_n can be off by more than 1% (2.7x the tolerance at 32 and r =
    2), a patch travel above a1/4 per sub-step too (heavy runners), and with finite friction
    steps above 1/8 cell overestimate the slip work where the trailing-edge slip zone, about
    |1 - eps - v*/(omega R)| (G*/E*) R / mu wide, spans about one to a few cells (+1.3% at
    1/4 cell, +7% at 1 cell; measured at eps 0.998 .. 0.99999, mu 0.3).

    Returns ``mean_v_star_over_omega_R`` (mean runner velocity over the second half of the
    periods, paper convention), ``slip_work`` (per period, in units of 2 G* a1^3),
    ``energy_residual`` (residual / work put in, ``Drive.energy``'s ``work_in``: drive and load
    work plus the runner's initial kinetic energy; positive = dissipated by the numerics; the
    work is floored at ``ENERGY_FLOOR`` x 2 G* a1^3 per period, so that a runner too light to
    load the contact does not divide round-off by round-off),
    ``seconds``; with ``record`` also the per-tick trajectory.  ``step_converged``,
    ``runner_steps_per_period`` and ``step_note`` (``step_status``) say whether the runner
    period got the sub-steps ``default_substeps`` asks for (not above omega_n/Omega = 100,
    where they are capped, nor with a coarser ``n_sub``): if not, the mean velocity is not
    guaranteed converged in the step."""
    delta, eps, w, resolution = _check_common(delta, eps, w, resolution)
    omega_n_ratio = check_omega_n_ratio(omega_n_ratio)
    mu = check_range("mu", mu, 0.0, math.inf, lo_open=True, allow_inf=True)
    vstar0_ratio = check_range("vstar0_ratio", vstar0_ratio, -1e3, 1e3)
    F_ext = check_range("F_ext", F_ext, -math.inf, math.inf)
    if n_sub is not None:
        n_sub = check_n_sub(n_sub)  # int(n_sub) below truncated 2.5 to 2
    periods, ticks_per_half = _check_run_length(periods, ticks_per_half, lo=2)
    wave = SquareWave(delta, eps, w, geo.a1, geo.R, geo.tau, direction)
    runner = dict(omega_n_ratio=omega_n_ratio, mu=mu, F_ext=F_ext, vstar0_ratio=vstar0_ratio)
    return _free_runner(wave, geo, resolution, periods, ticks_per_half, n_sub, record, runner)


def _free_runner(wave, geo, resolution, periods, ticks_per_half, n_sub, record, runner):
    """``simulate`` on its checked arguments: the runner of ``runner`` (omega_n_ratio, mu,
    F_ext, vstar0_ratio) driven by ``wave`` (``n_sub`` None: ``default_substeps``)."""
    r, mu, F_ext = runner["omega_n_ratio"], runner["mu"], runner["F_ext"]
    m = natural_frequency_mass(r, wave, geo.G_star)
    if math.isinf(m) and F_ext != 0.0:
        raise ValueError("F_ext needs a finite runner mass (omega_n_ratio > 0)")
    if n_sub is None:
        n_sub = default_substeps(r, wave, resolution, ticks_per_half, mu)
    params = DriveParams(geo.R, geo.E_star, geo.G_star, mu=mu, m=m, F_ext=F_ext)
    d, u, v = wave.ticks(int(periods), ticks_per_half)
    dt_tick = wave.dt_tick(ticks_per_half)
    direction, vstar0_ratio = wave.direction, runner["vstar0_ratio"]

    def run(vstar_ratio=None):  # free, or held at v* = vstar_ratio omega R
        drv = _drive(wave, geo, params, resolution)
        drv.reset(vstar0=direction * vstar0_ratio * wave.omega_R)
        vs = (
            None if vstar_ratio is None else np.full(d.size, direction * vstar_ratio * wave.omega_R)
        )
        return drv, drv.run(dt_tick=dt_tick, n_sub=int(n_sub), omega_R=u, v=v, d=d, vstar=vs)

    per = 2 * ticks_per_half
    t0 = time.perf_counter()
    if math.isinf(m):  # infinitely heavy: the constant v* whose period impulse vanishes

        def last_impulse(V):
            return direction * run(V)[1]["impulse"][-per:].sum()

        hi = abs(1 - wave.eps) + 1.0
        V = brentq(last_impulse, -hi, hi, xtol=1e-12 * hi, rtol=1e-12)
        drv, out = run(V)
    else:
        drv, out = run()
    seconds = time.perf_counter() - t0
    half = (int(periods) // 2) * per
    xs = out["xstar"]
    x_start = xs[-half - 1] if half < xs.shape[0] else 0.0
    mean_v = (xs[-1] - x_start) / (half * dt_tick)
    e = drv.energy
    unit = 2 * geo.G_star * wave.a1**3
    res = {
        "mean_v_star_over_omega_R": float(direction * mean_v / wave.omega_R),
        "slip_work": float(e["slip"] / periods / unit),
        "energy_residual": float(
            e["residual"] / max(e["work_in"], ENERGY_FLOOR * unit * int(periods))
        ),
        "seconds": seconds,
        "eq32": float(analytic.eq32(wave.delta, wave.eps, wave.w)) if wave.w >= 2 else None,
        "n_sub": int(n_sub),
        "resolution": resolution,
        "periods": int(periods),
        "omega_n_ratio": r,
        "mu": mu,
        **step_status(r, wave, int(n_sub), ticks_per_half),
    }
    if record:
        res["trajectory"] = out
        res["wave"] = wave
        res["energy"] = e
    return res


RUNNER_STEPS_PER_PERIOD = 128  # sub-steps per runner period 2 pi/omega_n (default_substeps)
RUNNER_RESOLVED_MAX = 100.0  # omega_n/Omega up to which the default resolves the runner period
RUNNER_CAPPED_MAX = 1000.0  # up to here capped at the r = 100 count; above, the patch rule only
PATCH_TRAVEL_MAX = 1 / 16  # patch travel per sub-step, in a1 (4 cells at 64 cells per a1) ...
PATCH_CELLS_FRICTION = 0.125  # ... and in cells with finite friction (the slip work's edge)
STEP_TOL_REL, STEP_TOL_EQ32 = 0.01, 1e-3  # stated step tolerance of the default (docstring)


def runner_steps_per_period(omega_n_ratio, wave: SquareWave, n_sub, ticks_per_half=1) -> float:
    """Sub-steps per runner period 2 pi/omega_n at ``n_sub`` sub-steps per tick (inf for an
    infinitely heavy or a massless runner: no runner period to resolve)."""
    r = omega_n_ratio
    if r == 0 or math.isinf(r):
        return math.inf
    return n_sub * wave.tau / (r * wave.dt_tick(ticks_per_half))


def default_substeps(
    omega_n_ratio, wave: SquareWave, resolution, ticks_per_half=1, mu=math.inf
) -> int:
    """Sub-steps per tick: the larger of two rules.

    * Patch: the patch travels at most a1/16 per sub-step (``PATCH_TRAVEL_MAX``; 4 cells at
      64 cells per a1) and, with finite friction, at most 1/8 cell (``PATCH_CELLS_FRICTION``:
      the slip work at the trailing edge).
    * Runner: ``RUNNER_STEPS_PER_PERIOD`` (128) sub-steps per runner period 2 pi/omega_n,
      i.e. 64 r per half period at omega_n/Omega = r, up to ``RUNNER_RESOLVED_MAX`` (100).
      Above it the count is capped at its r = 100 value (6400 per half period), and above
      ``RUNNER_CAPPED_MAX`` (1000) the runner period is not resolved at all (the patch rule
      alone: the runner step then blends into backward Euler and gives the massless limit,
      no net motion).  ``simulate`` says so in both cases (``step_converged`` False and a
      ``step_note``).

    The runner step is exact on the linear piece of the stuck contact (no numerical damping
    or detuning of the runner's ringing), a trapezoid in the force beyond it, and the slip
    work is second order in the step: the mean runner velocity and the slip work converge at
    second order in the sub-step, and the step error of the mean velocity depends on the
    sub-step, not on the cells (the same within 25% at 16, 64 and 256 cells per a1, r = 2 ..
    15).

    Measured (delta 0.7, w 2.5, 64 cells per a1, 40 periods; eps 0.1 with mu = inf and eps
    0.995 with mu 0.3), against the second-order Richardson extrapolation of the two finest
    runs of a ladder doubling the sub-steps up to 16384 .. 262144 per half period (successive
    differences falling 4x per doubling; the extrapolated values move by < 2e-9 omega R), for
    r in {0.1, 0.2, 0.3, 0.5, 0.7, 1, 1.25, 1.5, 1.75, 2, 2.5, 3, 3.5, 4, 5, 6, 7, 8, 10, 12,
    15, 20, 30, 50, 70, 100} (with infinite friction also 1.8, 1.9, 2.1, 2.2, 2.3, 2.4, 2.7,
    3.2, 4.5, 5.5): the error of the mean v*/(omega R) stays within
    ``STEP_TOL_REL`` (1%) of it or, where it is near zero, ``STEP_TOL_EQ32`` x Eq. 32 (the
    larger), at most 0.15 of that tolerance (r = 2: 1.3e-5 omega R, 0.32%; 0.13 at 2.1, 0.10
    at 2.5 and 3) with infinite friction and 0.007 of it with mu 0.3, where the slip work is
    within 0.14% (r <= 100) and the energy residual positive.  The smallest rules that pass:
    64 sub-steps per runner period (0.70 of the tolerance at r = 2; 32 give 2.7); a patch
    travel of a1/4 per sub-step with infinite friction (0.36 of it at r = 0.5; 5 a1/16: 1.1);
    with finite friction 1/8 cell keeps the slip work within 0.45% for trailing-edge slip
    zones 0.08 to 15 cells wide (eps 0.998 .. 0.99999, 16 to 64 cells per a1), where 1/4 cell
    is 1.3% and 1 cell 7% high (the zone spanning about one to a few cells); 128 per runner
    period and a1/16 leave a margin of about 4x in the error.

    Cap: from r ~ 70 on the converged mean velocity is itself below the tolerance (|v*| =
    2.4e-5, 7.3e-5, 5.4e-6, 6.6e-6, 4.0e-6, 1.9e-7 omega R at r = 70, 100, 200, 1000, 2000,
    1e4 with infinite friction; the tolerance 8.6e-5), so the massless limit is within it.
    Capped (100 < r <= 1000) the measured error was <= 1e-3 of the tolerance (0.04-1.4%
    relative) and the slip work 0.1-3.2% low (r = 200 .. 1000); unresolved (r = 2000, 1e4)
    the run gives the massless limit, 0.047 and 0.002 of the tolerance off.

    Cost (2-core machine, shared; 64 cells per a1, 40 periods): 2-3 / 3-4 / 5-7 / 6-9 /
    12-13 ms at r = 2 / 3 / 5 / 7 / 10 with infinite friction and 62-78 ms with mu 0.3 (the
    patch rule's 1280 sub-steps per half period up to r = 20); at the r = 100 count (r = 100
    .. 1000) 0.1-0.2 s with infinite friction and 0.4-0.9 s with mu 0.3.  The patch rule governs
    below r = 0.625 with infinite friction and below r = 20 with finite friction (w 2.5, 64
    cells per a1)."""
    tick = wave.dt_tick(ticks_per_half)
    travel = wave.omega_R * tick / wave.a1  # patch travel per tick, in a1
    n = max(1.0, travel / PATCH_TRAVEL_MAX)
    if math.isfinite(mu):
        n = max(n, travel * resolution / PATCH_CELLS_FRICTION)
    r = omega_n_ratio
    if 0 < r <= RUNNER_CAPPED_MAX:
        rr = min(r, RUNNER_RESOLVED_MAX)
        n = max(n, RUNNER_STEPS_PER_PERIOD * rr * tick / wave.tau)
    # (1 - 1e-12): 160.00000000000003 cells from round-off asks for 160 sub-steps, not 161
    return int(math.ceil(n * (1.0 - 1e-12)))


def step_status(omega_n_ratio, wave: SquareWave, n_sub, ticks_per_half=1) -> dict:
    """Whether ``n_sub`` sub-steps per tick resolve the runner period as ``default_substeps``
    asks (``step_converged``), the ``runner_steps_per_period`` and a ``step_note`` ('' when
    resolved) naming how far off it may be."""
    r = omega_n_ratio
    have = runner_steps_per_period(r, wave, n_sub, ticks_per_half)
    if math.isinf(have):
        return dict(step_converged=True, runner_steps_per_period=have, step_note="")
    want = RUNNER_STEPS_PER_PERIOD
    if have >= want * (1 - 1e-9):
        return dict(step_converged=True, runner_steps_per_period=have, step_note="")
    note = (
        f"runner period resolved by {have:.3g} sub-steps, below the {want:g} that "
        f"default_substeps asks for at omega_n/Omega = {r:g}: the mean velocity is not "
        f"guaranteed converged in the step to {STEP_TOL_REL:.0%} (its step error is second "
        "order)"
    )
    if have < 2 * math.pi / 2.0:
        note += (
            "; below about 3 sub-steps per runner period (omega_n dt > 2) the runner "
            "step blends into backward Euler, which damps the runner's ringing and tends "
            "to the massless limit"
        )
    if r > RUNNER_CAPPED_MAX:
        note += (
            f" (above omega_n/Omega = {RUNNER_CAPPED_MAX:g} the default does not resolve "
            "the runner period: the step gives the massless limit, no net motion, which "
            "is within the step tolerance where the mean velocity is itself below it, as "
            "measured at delta 0.7, w 2.5 from omega_n/Omega ~ 70 on)"
        )
    elif r > RUNNER_RESOLVED_MAX:
        note += (
            f" (sub-steps capped at their omega_n/Omega = {RUNNER_RESOLVED_MAX:g} value; "
            "measured at delta 0.7, w 2.5 up to omega_n/Omega = 1000 the capped default "
            "stayed within 1e-3 of the step tolerance of the converged mean velocity, "
            "the slip work within 3.2%)"
        )
    return dict(step_converged=False, runner_steps_per_period=have, step_note=note)
