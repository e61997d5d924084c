"""The stability cases at the env's own settings: the default scene's tick, resolution and
"auto" sub-steps, runners from omega_n/Omega = 1e-3 to 1e4 and massless, and the approach to
the massless runner as the runner gets lighter."""

from __future__ import annotations

import math
import time

import numpy as np

from rolling_env.env import scenes
from rolling_env.physics import _kernel as _K
from rolling_env.physics.model import Drive, DriveParams
from rolling_env.studies.stability_checks import FLOOR, STEP_TOL_REL, _finite, _row

# ----------------------------------------------------------------------------- env settings
ENV_SCENE = "default"
ENV_PERIODS = 32  # nominal periods of the square wave
ENV_RATIOS = (1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0, 1e3, 1e4, math.inf)
RESID_TOL_ENV = 1e-3  # env settings: energy created may not exceed 1e-3 of the work put in
ENV_CONTINUITY_FROM = 100.0  # |x* - x*_massless| non-increasing from this omega_n/Omega on ...
ENV_CONTINUITY_TOL = 0.1  # ... and below this many scene tolerances at the largest ratio
ENV_STEP_TOL_ABS = 0.01  # env step check: change of x* at 4x sub-steps, in scene tolerances


def env_mass(scene, r: float) -> float:
    """Runner mass [kg] for omega_n/Omega = r on a scene: omega_n = sqrt(2 a_max G*/m) with
    a_max the contact radius at N_max, Omega = 2 pi / period; r = inf is massless."""
    if math.isinf(r):
        return 0.0
    a = scenes.contact_radius_max(scene)
    return 2 * a * scene.G_star / (r * 2 * math.pi / scene.period) ** 2


def env_square_wave(scene, periods: int):
    """(N, omega R, v) per tick: forth N = 0.8 N_max, omega R = +0.7 omega_R_max; back N = 0.4
    N_max, -0.7 omega_R_max; v = omega R (1 - 0.3 creep_max); ticks_per_period/2 ticks each."""
    tpp = scene.ticks_per_period
    k = np.arange(periods * tpp)
    forth = (k % tpp) < tpp // 2
    N = np.where(forth, 0.8, 0.4) * scene.N_max
    u = np.where(forth, 1.0, -1.0) * 0.7 * scene.omega_R_max
    return N, u, u * (1 - 0.3 * scene.creep_max)


def env_run(
    r: float, scene_name: str = ENV_SCENE, periods: int = ENV_PERIODS, sub_factor: int = 1
) -> dict:
    """The square wave ``env_square_wave`` on a scene whose runner mass gives omega_n/Omega =
    r, at the scene's own tick and sub-steps (``Scene.n_sub``, "auto" on the default scene;
    times ``sub_factor``), through a drive built as the env builds it (``env.build_drive``:
    grid over +-stroke_roll, a_ref = a_max, the scene's resolution, t_ref = period) but with
    the energy ledger.  Energies are per period in 2 G* a_max^3, x* in scene tolerances."""
    base = scenes.load_scene(scene_name)
    m = env_mass(base, r)
    sc = base.replace(runner_mass=m)
    a = scenes.contact_radius_max(sc)
    params = DriveParams(sc.R, sc.E_star, sc.G_star, mu=sc.mu, m=sc.runner_mass, F_ext=sc.F_ext)
    drv = Drive(
        params,
        a_ref=a,
        resolution=sc.resolution,
        stroke=(-sc.stroke_roll, sc.stroke_roll),
        a_max=a,
        t_ref=sc.period,
        ledger=True,
    )
    drv.reset()
    N, u, v = env_square_wave(sc, periods)
    n_sub = sc.n_sub * sub_factor
    t = time.perf_counter()
    out = drv.run(dt_tick=sc.dt, n_sub=n_sub, omega_R=u, v=v, N=N)
    sec = time.perf_counter() - t
    e = drv.energy
    unit = 2 * sc.G_star * a**3 * periods  # [J]
    floor = FLOOR * unit
    supply = e["drive"] + e["ext"] + e["kinetic_start"]
    return dict(
        r=r,
        mass=m,
        n_sub=n_sub,
        seconds=sec,
        finite=_finite([], out.values()),
        residual=float(e["residual"] / max(e["work_in"], floor)),
        floored=bool(e["work_in"] < floor),
        state_ok=bool(e["elastic"] + e["kinetic"] <= supply + floor),
        energy={k: float(x / unit) for k, x in e.items()},
        x=float(out["xstar"][-1] / sc.tolerance),
        runner_steps=(math.inf if m == 0 else n_sub * sc.ticks_per_period / r),
        # the wavelength 2 pi omega R / omega_n of the runner's ringing on the contact
        ringing_cells=(
            0.7 * sc.omega_R_max * sc.period / r / (a / sc.resolution) if m > 0 else 0.0
        ),
        tolerance=sc.tolerance,
        scene=sc.name,
    )


class _EnvSweep:
    """``env_run`` for each ratio (and sub-step factor), run once and shared by the cases."""

    def __init__(self, scene_name=ENV_SCENE, periods=ENV_PERIODS):
        self.scene_name, self.periods, self.rows = scene_name, periods, {}

    def __call__(self, r, sub_factor=1):
        if (r, sub_factor) not in self.rows:
            self.rows[r, sub_factor] = env_run(r, self.scene_name, self.periods, sub_factor)
        return self.rows[r, sub_factor]


_LEDGER_TERMS = ("drive", "ext", "elastic", "release", "slip", "snap", "kinetic")


def _env_case(sweep: _EnvSweep, r, step_check=True):
    """One ratio at the scene's sub-steps; with ``step_check`` also at 4x the sub-steps (the
    change of x* and of the residual, and the ledger term that changed most)."""

    def run():
        x = sweep(r)
        ml = sweep(math.inf)
        parts = _env_notes(x, ml, r, sweep.periods)
        step, conv = "-", None
        if step_check:
            x4 = sweep(r, 4)
            dx = abs(x4["x"] - x["x"])
            conv = bool(dx <= max(STEP_TOL_REL * abs(x4["x"]), ENV_STEP_TOL_ABS))
            step = f"x* {dx:.1e} tol., residual {x4['residual']:.2g} at 4x" + (
                "" if conv else " NOT converged"
            )
            parts += _env_residual_notes(x, x4)
        return _row(
            x["finite"],
            x["residual"],
            x["state_ok"],
            "; ".join(parts),
            step=step,
            converged=conv,
            details=x,
            resid_tol=RESID_TOL_ENV,
        )

    return run


def _env_notes(x, ml, r, periods) -> list:
    """The outcome of ``env_run`` ``x`` (``ml``: the massless runner's): the runner, its
    final x*, the work put in, and how far the runner step is backward Euler."""
    S = x["runner_steps"]
    parts = [
        f"m = {x['mass']:.3g} kg, {x['n_sub']} sub-steps per tick"
        + ("" if math.isinf(S) else f" ({S:.3g} per runner period)")
        + f"; x* after {periods} periods {x['x']:.4g} tolerances"
    ]
    if math.isinf(r):
        parts.append("massless runner: force equilibrium, follows the sphere")
    else:
        parts.append(f"{abs(x['x'] - ml['x']):.3g} tolerances from the massless runner's")
    e = x["energy"]
    parts.append(
        f"work put in {e['work_in']:.3g} x 2 G* a_max^3 per period"
        + (
            f" (below the round-off floor {FLOOR:g}: the residual is relative to the floor)"
            if x["floored"]
            else ""
        )
        + f", slip work {e['slip']:.3g}"
    )
    if not math.isinf(S):
        q = (2 * math.pi / S) ** 2 / _K.THETA2_BLEND
        lam = 1.0 / (1.0 + q**4)
        if lam < 0.99:
            parts.append(
                f"runner period resolved by only {S:.3g} sub-steps (omega_n dt = "
                f"{2 * math.pi / S:.2g} at N_max): the runner step is "
                f"{1 - lam:.0%} backward Euler (the kernel's blend), which "
                "damps the ringing and tends to the massless limit"
            )
    return parts


def _env_residual_notes(x, x4) -> list:
    """Where energy is created beyond ``RESID_TOL_ENV``, the ledger term that changes most at
    4x the sub-steps (``x4``); where over 10% is dissipated the same at 4x, why."""
    e, e4 = x["energy"], x4["energy"]
    if x["residual"] <= -RESID_TOL_ENV:
        w = e["work_in"]
        w4 = e4["work_in"]
        k = max(_LEDGER_TERMS, key=lambda t: abs(e[t] / w - e4[t] / w4))
        return [
            f"energy created beyond {RESID_TOL_ENV:g} of the work put in; at "
            f"4x the sub-steps the residual is {x4['residual']:+.2g}, and the "
            f"ledger term that changes most is the {k} work: {e[k] / w:.4g} of "
            f"the work put in, {e4[k] / w4:.4g} at 4x"
            + (
                ": the slip work, second order in the sub-step, is overbooked at "
                "the scene's sub-steps"
                if k == "slip" and e[k] / w > e4[k] / w4
                else ""
            )
        ]
    if x["residual"] > 0.1 and abs(x4["residual"] - x["residual"]) < (0.1 * x["residual"]):
        return [
            f"residual {x['residual']:.2g}, the same at 4x the sub-steps: "
            "the uniform cells average out the runner's ringing imprinted on "
            f"the stuck contact (its wavelength {x['ringing_cells']:.2g} "
            "cells), not the step"
        ]
    return []


def _env_continuity_case(sweep: _EnvSweep, ratios):
    """|x* - x*_massless| non-increasing from ``ENV_CONTINUITY_FROM`` on, below
    ``ENV_CONTINUITY_TOL`` tolerances at the largest finite ratio."""

    def run():
        rs = [r for r in ratios if ENV_CONTINUITY_FROM <= r < math.inf]
        ml = sweep(math.inf)["x"]
        d = [abs(sweep(r)["x"] - ml) for r in rs]
        mono = all(b <= a * (1 + 1e-9) + 1e-12 for a, b in zip(d, d[1:]))
        close = d[-1] < ENV_CONTINUITY_TOL
        checks = {
            f"non-increasing from omega_n/Omega = {ENV_CONTINUITY_FROM:g} on": mono,
            f"below {ENV_CONTINUITY_TOL:g} tolerance at {rs[-1]:g}": close,
        }
        return _row(
            True,
            float("nan"),
            True,
            "|x* - x*_massless| in scene tolerances at omega_n/Omega = "
            + ", ".join(f"{r:g}: {x:.3g}" for r, x in zip(rs, d))
            + f"; non-increasing: {mono}; below {ENV_CONTINUITY_TOL:g} at {rs[-1]:g}: "
            f"{close} (the runs of the cases above)",
            ledger=False,
            checks=checks,
            details=dict(ratios=rs, dist=d),
        )

    return run
