"""Slow, plain-numpy REFERENCE of the MDR drive model: the textbook "plain spring row".

The model: docs/physics.md.  A row of independent springs (spacing dx, centres
x_i = x_lo + (i + 0.5) dx) in the frame that moves with the sphere; a spring is in contact
iff its centre is (uN_i = d - (x_i - c)^2 / R > 0). Readable rather than fast; no numba,
float64 throughout. The fast kernel is tested against this, and it is a line on the
work-precision plot.
"""

from __future__ import annotations

import math

import numpy as np


def _row(x_lo, x_hi, dx):
    """Spring centres x_lo + (i + 0.5) dx covering [x_lo, x_hi]."""
    n = max(1, math.ceil((x_hi - x_lo) / dx - 1e-9))
    return x_lo + (np.arange(n) + 0.5) * dx


def _bisect(residual, lo, hi):
    """Root of a non-decreasing residual on [lo, hi], bisected to the last float."""
    for _ in range(400):
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:
            break
        if residual(mid) > 0.0:
            hi = mid
        else:
            lo = mid
    return 0.5 * (lo + hi)


_KEYS = (
    "T",
    "impulse",
    "N",
    "vstar",
    "xstar",
    "c",
    "slip_work",
    "release_work",
    "elastic",
    "drive_work",
    "runner_work",
)


def _per_tick(d, omegaR, v, vstar, F_ext):
    """The per-tick inputs as float64 arrays, F_ext broadcast from a scalar; each must be
    1-D, one value per tick, without NaN."""
    ticks = {
        name: np.atleast_1d(np.asarray(a, dtype=np.float64))
        for name, a in dict(d=d, omegaR=omegaR, v=v, vstar=vstar).items()
    }
    n_t = ticks["d"].size
    ticks["F_ext"] = (
        np.broadcast_to(np.asarray(F_ext, dtype=np.float64), (n_t,))
        if np.ndim(F_ext) == 0
        else np.asarray(F_ext, dtype=np.float64)
    )
    for name, a in ticks.items():
        if a.ndim != 1 or a.size != n_t:
            raise ValueError(
                f"{name} must be 1-D with one value per tick: shape {a.shape}, "
                f"but d has {n_t} ticks"
            )
        if np.isnan(a).any():
            raise ValueError(f"{name} contains NaN")
    return ticks


def _checked_inputs(p, n_sub, d, omegaR, v, vstar, F_ext):
    """The per-tick inputs (_per_tick), after raising ValueError on a NaN or on a parameter
    out of its range (p: the scalar parameters by name)."""
    for name, val in p.items():
        if np.isnan(val):
            raise ValueError(f"{name} is NaN")
    ticks = _per_tick(d, omegaR, v, vstar, F_ext)
    if not p["dx"] > 0:
        raise ValueError(f"dx must be > 0, got {p['dx']}")
    if int(n_sub) != n_sub or n_sub < 1:
        raise ValueError(f"n_sub must be an integer >= 1, got {n_sub}")
    if not p["x_hi"] > p["x_lo"]:
        raise ValueError(f"x_hi must exceed x_lo, got [{p['x_lo']}, {p['x_hi']}]")
    for name in ("R", "E_star", "G_star", "dt_tick"):
        if not 0 < p[name] < np.inf:
            raise ValueError(f"{name} must be finite and > 0, got {p[name]}")
    if p["mu"] < 0:
        raise ValueError(f"mu must be >= 0, got {p['mu']}")
    m = p["m"]
    if m < 0:
        raise ValueError(f"m must be >= 0, got {m}")
    if m == 0 and np.any(ticks["F_ext"] != 0):
        raise ValueError("F_ext must be 0 when m == 0 (a massless runner cannot carry a load)")
    if m == np.inf and not np.isfinite(ticks["vstar"]).all():
        raise ValueError("vstar must be finite when m is inf (prescribed)")
    return ticks


class _SpringRow:
    """The row's state between sub-steps (tangential deflections, patch centre, runner) and
    the works accumulated so far."""

    def __init__(self, *, R, E_star, G_star, mu, m, x_lo, x_hi, dx, dt, c0, vstar0):
        self.x = _row(x_lo, x_hi, dx)
        self.R, self.E_star, self.G_star, self.mu, self.m, self.dt = R, E_star, G_star, mu, m, dt
        self.kN, self.kT = E_star * dx, G_star * dx
        self.uT = np.zeros_like(self.x)
        self.c, self.vs, self.xs = float(c0), float(vstar0), 0.0
        self.slip_w = self.release_w = self.drive_w = self.runner_w = 0.0

    def substep(self, d_k, wR, v_k, F_k, vstar_k):
        """Advance one sub-step; returns the tangential force T after it, its mean over the
        sub-step, and the contact mask and normal deflections uN it ran with."""
        dt, kT, mu = self.dt, self.kT, self.mu
        # 1. roll the profile over the springs
        self.c += wR * dt
        uN = d_k - (self.x - self.c) ** 2 / self.R
        contact = uN > 0.0
        # 2. release springs that left contact: their elastic energy is dissipated
        gone = ~contact
        self.release_w += 0.5 * kT * np.sum(self.uT[gone] ** 2)
        self.uT[gone] = 0.0
        T_old = kT * np.sum(self.uT)  # the force at the start of the sub-step
        # 3. trial deflection as a function of the new runner velocity, then Coulomb
        lim = np.where(contact, mu * (self.E_star / self.G_star) * uN, 0.0) if mu < np.inf else None

        # the runner's displacement over the sub-step: the trapezoid of its velocities
        # for a free runner (implicit trapezoid rule, second order), its new velocity
        # for a prescribed or massless one
        vs_old = self.vs if 0 < self.m < np.inf else None
        uT = self.uT

        def mean_v(vs_new):
            return vs_new if vs_old is None else 0.5 * (vs_old + vs_new)

        def trial(vs_new):
            u_tr = np.where(contact, uT + (wR - v_k - mean_v(vs_new)) * dt, 0.0)
            u_cl = u_tr if lim is None else np.clip(u_tr, -lim, lim)
            return u_tr, u_cl, kT * np.sum(u_cl)

        vs_new = self._new_velocity(trial, contact, uN, lim, T_old, wR - v_k, F_k, vstar_k)
        # 4. commit
        u_tr, u_cl, T = trial(vs_new)
        if lim is not None:
            self.slip_w += np.sum(mu * self.kN * np.where(contact, uN, 0.0) * np.abs(u_tr - u_cl))
        self.uT = u_cl
        vm = mean_v(vs_new)
        self.vs = float(vs_new)
        self.xs += vm * dt
        T_mean = T if vs_old is None else 0.5 * (T_old + T)
        self.drive_w += T_mean * (wR - v_k) * dt
        self.runner_w += T_mean * vm * dt
        return T, T_mean, contact, uN

    def _new_velocity(self, trial, contact, uN, lim, T_old, slide, F_k, vstar_k):
        """The runner's velocity at the end of the sub-step: prescribed, or the one that
        balances its momentum (m > 0) or its force (massless) against T(vs_new) = trial's.
        slide: omegaR - v over the sub-step."""
        m, vs, dt, kT = self.m, self.vs, self.dt, self.kT
        n_c = int(contact.sum())
        if m == np.inf:  # prescribed runner
            return vstar_k
        if lim is None:  # T affine: T0 - K dt vs_new
            T0 = kT * np.sum(np.where(contact, self.uT + slide * dt, 0.0))
            K = kT * n_c
            if m > 0:  # m (v1 - v0) = dt/2 (T_old + T1) + dt F, T1 = T0 - K dt (v0 + v1)/2
                a_ = 0.5 * K * dt * dt
                return (m * vs + 0.5 * dt * (T_old + T0 - 0.5 * K * dt * vs) + dt * F_k) / (
                    m + 0.5 * a_
                )
            return T0 / (K * dt) if n_c > 0 else 0.0
        if m > 0:  # dynamics, finite friction
            T_max = np.sum(self.mu * self.kN * np.where(contact, uN, 0.0))
            return _bisect(
                lambda s: m * (s - vs) - 0.5 * dt * (T_old + trial(s)[2]) - dt * F_k,
                vs + dt * (F_k - T_max) / m,
                vs + dt * (F_k + T_max) / m,
            )
        if n_c == 0:  # massless, nothing to hold it
            return 0.0
        # massless: T(vs_new) = 0
        base = slide + self.uT[contact] / dt
        return _bisect(
            lambda s: -trial(s)[2],
            np.min(base - lim[contact] / dt),  # all saturated at +lim
            np.max(base + lim[contact] / dt),  # all saturated at -lim
        )


def naive_run(
    *,
    R,
    E_star,
    G_star,
    mu,
    m,
    F_ext,
    x_lo,
    x_hi,
    dx,
    d,
    omegaR,
    v,
    vstar,
    dt_tick,
    n_sub,
    c0=0.0,
    vstar0=0.0,
):
    """d, omegaR, v, vstar: 1-D arrays, one value per control tick (piecewise constant).
    vstar is used only when m is inf (prescribed runner velocity); ignored otherwise.
    F_ext: scalar or one value per tick. Returns a dict of 1-D arrays, one entry per tick,
    values at the END of each tick unless said:
      'T'        tangential force [N] at the end of the tick
      'impulse'  integral of T dt over the tick [N s] (sum of T_after_substep * dt)
      'N'        normal force sum kN uN [N]
      'vstar'    runner velocity [m/s]
      'xstar'    runner displacement [m]
      'c'        patch centre [m]
      'slip_work' cumulative [J]
      'release_work' cumulative [J]
      'elastic'  tangential elastic energy sum 0.5 kT uT^2 [J]
      'drive_work' cumulative integral of T*(omegaR - v) dt [J]
      'runner_work' cumulative integral of T*vstar dt [J]
    and 'uT' final array, 'x' spring positions."""
    params = dict(
        R=R,
        E_star=E_star,
        G_star=G_star,
        mu=mu,
        m=m,
        x_lo=x_lo,
        x_hi=x_hi,
        dx=dx,
        dt_tick=dt_tick,
        c0=c0,
        vstar0=vstar0,
    )
    ticks = _checked_inputs(params, n_sub, d, omegaR, v, vstar, F_ext)

    row = _SpringRow(dt=dt_tick / n_sub, **{k: p for k, p in params.items() if k != "dt_tick"})
    n_t = ticks["d"].size
    out = {k: np.zeros(n_t) for k in _KEYS}
    for k in range(n_t):
        d_k, wR, v_k = ticks["d"][k], ticks["omegaR"][k], ticks["v"][k]
        impulse = 0.0
        for _ in range(int(n_sub)):
            T, T_mean, contact, uN = row.substep(d_k, wR, v_k, ticks["F_ext"][k], ticks["vstar"][k])
            impulse += T_mean * row.dt
        out["T"][k], out["impulse"][k] = T, impulse
        out["N"][k] = row.kN * np.sum(np.where(contact, uN, 0.0))
        out["vstar"][k], out["xstar"][k], out["c"][k] = row.vs, row.xs, row.c
        out["slip_work"][k], out["release_work"][k] = row.slip_w, row.release_w
        out["elastic"][k] = 0.5 * row.kT * np.sum(row.uT**2)
        out["drive_work"][k], out["runner_work"][k] = row.drive_w, row.runner_w
    out["uT"], out["x"] = row.uT, row.x
    return out


def naive_normal_force(d, R, E_star, dx, c=0.0, x_lo=None, x_hi=None):
    """N = sum kN uN over a row covering the contact (default: symmetric about c)."""
    if not dx > 0:
        raise ValueError(f"dx must be > 0, got {dx}")
    if x_lo is None or x_hi is None:
        half = (math.ceil(math.sqrt(max(d, 0.0) * R) / dx) + 2) * dx
        x_lo, x_hi = c - half, c + half
    x = _row(x_lo, x_hi, dx)
    uN = d - (x - c) ** 2 / R
    return E_star * dx * np.sum(uN[uN > 0.0])


def naive_mindlin(mu, R, E_star, G_star, d, dx, u_values):
    """Press to d, then displace tangentially through non-decreasing u_values (runner held,
    no rolling: omegaR = 0, v = -du/dt, vstar = 0 prescribed). Returns T at each u."""
    u = np.asarray(u_values, dtype=np.float64)
    if u.ndim != 1 or np.isnan(u).any() or np.any(np.diff(np.concatenate([[0.0], u])) < 0):
        raise ValueError("u_values must be 1-D, non-NaN, >= 0 and non-decreasing")
    half = (math.ceil(math.sqrt(d * R) / dx) + 2) * dx
    dt_tick = 1.0
    v = -np.diff(np.concatenate([[0.0], u])) / dt_tick
    zeros = np.zeros_like(u)
    res = naive_run(
        R=R,
        E_star=E_star,
        G_star=G_star,
        mu=mu,
        m=np.inf,
        F_ext=0.0,
        x_lo=-half,
        x_hi=half,
        dx=dx,
        d=np.full_like(u, d),
        omegaR=zeros,
        v=v,
        vstar=zeros,
        dt_tick=dt_tick,
        n_sub=1,
    )
    return res["T"]


def eq32(delta, eps, w):
    """v*/(omega R) of physics.md Eq. 32."""
    return (
        (1 - eps)
        * (4 / 3 * (1 - delta**1.5) - 2 * w * (1 - delta))
        / (4 / 3 - 4 * delta - 2 * w * (1 + delta))
    )


def working_point(
    delta, eps, w, dx_per_a, R=1e-3, E_star=115e9, G_ratio=0.824, d1=1e-7, omegaR=1e-3, periods=3
):
    """Quasi-static square wave (infinite friction, prescribed vstar): v*/(omega R) from the
    zero of the last period's impulse, which is affine in vstar."""
    a1 = math.sqrt(R * d1)
    dx, W = a1 / dx_per_a, w * a1
    half_tau = W / omegaR
    n_sub = math.ceil(W / dx)  # omegaR dt <= dx
    sgn = np.tile([1.0, -1.0], periods)
    kw = dict(
        R=R,
        E_star=E_star,
        G_star=G_ratio * E_star,
        mu=np.inf,
        m=np.inf,
        F_ext=0.0,
        x_lo=-1.5 * a1 - 2 * dx,
        x_hi=W + 1.5 * a1 + 2 * dx,
        dx=dx,
        d=np.where(sgn > 0, d1, delta * d1),
        omegaR=sgn * omegaR,
        v=sgn * eps * omegaR,
        dt_tick=half_tau,
        n_sub=n_sub,
        c0=0.0,
    )
    imp = [
        naive_run(vstar=np.full(sgn.size, s), **kw)["impulse"][-2:].sum()
        for s in (0.0, 0.1 * omegaR)
    ]
    return -imp[0] / ((imp[1] - imp[0]) / (0.1 * omegaR)) / omegaR


if __name__ == "__main__":
    R, E, G, mu, d1 = 1e-3, 115e9, 0.824 * 115e9, 0.3, 1e-7
    a1 = math.sqrt(R * d1)
    N_hertz = 4 / 3 * E * math.sqrt(R) * d1**1.5
    print("(1) normal force vs Hertz, N =", N_hertz, "N")
    for per_a in (50, 100):
        N = naive_normal_force(d1, R, E, a1 / per_a)
        N_off = naive_normal_force(
            d1, R, E, a1 / per_a, c=0.37 * a1 / per_a, x_lo=-1.1 * a1, x_hi=1.1 * a1
        )
        print(
            f"    dx = a/{per_a:<3d}: rel. error {N / N_hertz - 1:+.3e} (grid centred on the"
            f" contact), {N_off / N_hertz - 1:+.3e} (contact shifted by 0.37 dx)"
        )
    u_star = mu * E * d1 / G
    u = np.linspace(0.0, 1.2 * u_star, 241)[1:]
    T = naive_mindlin(mu, R, E, G, d1, a1 / 100, u)
    T_ex = mu * N_hertz * (1 - np.clip(1 - u / u_star, 0.0, None) ** 1.5)
    rel = np.abs(T / T_ex - 1)
    print(
        f"(2) Mindlin at dx = a/100: max rel. error {rel.max():.3e} "
        f"(at u/u* = {u[rel.argmax()] / u_star:.3f}); "
        f"for u/u* >= 0.1: {rel[u >= 0.1 * u_star].max():.3e}"
    )
    ref = eq32(0.7, 0.1, 2.5)
    print(f"(3) working point (delta, eps, w) = (0.7, 0.1, 2.5): Eq. 32 v*/(omega R) = {ref:.6f}")
    for per_a in (50, 64, 100, 128, 200):
        got = working_point(0.7, 0.1, 2.5, per_a)
        print(f"    dx = a1/{per_a:<3d}: naive {got:.6f}, rel. error {got / ref - 1:+.3e}")
