"""Analytic reference results of the drive (paper Eqs. 1-3, 27-29, 32; Cattaneo-Mindlin).

All functions take scalars or numpy arrays (broadcast), SI units, and reject out-of-range
input with a ``ValueError`` naming the parameter and its range.
"""
from __future__ import annotations

import numpy as np


def _arr(name, x, lo=-np.inf, hi=np.inf, lo_open=False, hi_open=False, allow_inf=False):
    a = np.asarray(x, dtype=np.float64)
    if np.any(np.isnan(a)):
        raise ValueError(f"{name} must not be NaN")
    if not allow_inf and np.any(np.isinf(a)):
        raise ValueError(f"{name} must be finite")
    bad = (a < lo) | (a > hi)
    if lo_open:
        bad |= a == lo
    if hi_open:
        bad |= a == hi
    if np.any(bad):
        lb, rb = ("(" if lo_open else "["), (")" if hi_open else "]")
        raise ValueError(f"{name} must be in {lb}{lo:g}, {hi:g}{rb}, got {a[bad].ravel()[0]!r}")
    return a


def _out(a):
    return float(a) if np.ndim(a) == 0 else a


# ----------------------------------------------------------------------------- materials
def effective_moduli(E1, nu1, E2, nu2):
    """Eq. 1: (E*, G*) [Pa] of two elastic bodies (Young moduli E [Pa], Poisson ratios nu):
    1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2,  1/G* = (2-nu1)/(4 G1) + (2-nu2)/(4 G2)."""
    E1 = _arr("E1", E1, 0, np.inf, lo_open=True)
    E2 = _arr("E2", E2, 0, np.inf, lo_open=True)
    nu1 = _arr("nu1", nu1, 0, 0.5)
    nu2 = _arr("nu2", nu2, 0, 0.5)
    G1, G2 = E1 / (2 * (1 + nu1)), E2 / (2 * (1 + nu2))
    E_star = 1 / ((1 - nu1 ** 2) / E1 + (1 - nu2 ** 2) / E2)
    G_star = 1 / ((2 - nu1) / (4 * G1) + (2 - nu2) / (4 * G2))
    return _out(E_star), _out(G_star)


def g_over_e(nu):
    """G*/E* for two bodies of one material with Poisson ratio nu: 2(1-nu)/(2-nu)."""
    nu = _arr("nu", nu, 0, 0.5)
    return _out(2 * (1 - nu) / (2 - nu))


# ----------------------------------------------------------------------------- Hertz
def hertz_indentation(N, R, E_star):
    """Eq. 2: indentation d [m] = (3 N / (4 E* sqrt(R)))^(2/3) for normal force N [N]."""
    N = _arr("N", N, 0)
    R = _arr("R", R, 0, np.inf, lo_open=True)
    E_star = _arr("E_star", E_star, 0, np.inf, lo_open=True)
    return _out((3 * N / (4 * E_star * np.sqrt(R))) ** (2 / 3))


def hertz_force(d, R, E_star):
    """Normal force N [N] = 4/3 E* sqrt(R) d^(3/2) for indentation d [m]."""
    d = _arr("d", d, 0)
    R = _arr("R", R, 0, np.inf, lo_open=True)
    E_star = _arr("E_star", E_star, 0, np.inf, lo_open=True)
    return _out(4 / 3 * E_star * np.sqrt(R) * d ** 1.5)


def contact_radius(d, R):
    """Eq. 3: contact radius a [m] = sqrt(R d)."""
    d = _arr("d", d, 0)
    R = _arr("R", R, 0, np.inf, lo_open=True)
    return _out(np.sqrt(R * d))


def tangential_stiffness(a, G_star):
    """Stiffness of a stuck contact of radius a [m]: 2 a G* [N/m]."""
    return _out(2 * _arr("a", a, 0) * _arr("G_star", G_star, 0, np.inf, lo_open=True))


def natural_frequency(a1, G_star, m):
    """omega_n = sqrt(2 a1 G* / m) [rad/s] of a runner of mass m [kg] on the stuck contact."""
    k = tangential_stiffness(a1, G_star)
    m = _arr("m", m, 0, np.inf, lo_open=True)
    return _out(np.sqrt(k / m))


# ----------------------------------------------------------------------------- working points
def steady_forces(delta, eps, vstar_ratio, a1, G_star):
    """Eqs. 27-28: steady rolling forces [N] of the forth and back steps,
    T1 = 2 G* a1^2 (1 - eps - V), T2 = 2 G* a2^2 (-1 + eps - V), a2^2 = delta a1^2,
    V = v*/(omega R)."""
    delta = _arr("delta", delta, 0, 1)
    eps = _arr("eps", eps)
    V = _arr("vstar_ratio", vstar_ratio)
    a1 = _arr("a1", a1, 0)
    G_star = _arr("G_star", G_star, 0, np.inf, lo_open=True)
    T1 = 2 * G_star * a1 ** 2 * (1 - eps - V)
    T2 = 2 * G_star * delta * a1 ** 2 * (-1 + eps - V)
    return _out(T1), _out(T2)


def eq29(delta, eps):
    """Eq. 29 (= Eq. 11): v*/(omega R) = (1 - eps)(1 - delta)/(1 + delta), steady rolling
    (large amplitude)."""
    delta = _arr("delta", delta, 0, 1)
    eps = _arr("eps", eps)
    return _out((1 - eps) * (1 - delta) / (1 + delta))


def impulse_coefficients(delta, w):
    """(P, Q) with the period impulse I = (1 - eps) P - V Q in units of G* a1^3/(omega R).

    Derivation (physics.md kinematics, a1 = omega R = 1, b = sqrt(delta)): with creep rates
    s1 = (1-eps) - V (forth) and s2 = -(1-eps) - V (back), I = s1 C1 + s2 C2 where
    C1 = 2w - 4/3 + 2 b^2 + 2/3 b^3 (time-in-contact integral of the forth step plus the forth
    deflection the back step carries) and C2 = 2 b^2 w + 2 b^2 - 2/3 b^3; hence
    P = C1 - C2 = 2w(1-delta) - 4/3(1 - delta^1.5), Q = C1 + C2 = 2w(1+delta) - 4/3 + 4 delta,
    valid for w >= 2 (every spring released once per step).  For 1 + sqrt(delta) <= w < 2 the
    forth-step springs do not all release and C1 gains k = (2 - w)^3 / 6 (physics.md; checked
    against the simulation in tests/test_physics.py), so P and Q both gain k.
    """
    delta = _arr("delta", delta, 0, 1)
    w = _arr("w", w, 0, np.inf, lo_open=True)
    low = w < 1 + np.sqrt(delta)
    if np.any(low):
        raise ValueError("w must be >= 1 + sqrt(delta): below, some springs never release and "
                         "there is no steady working point")
    k = np.where(w < 2, (2 - w) ** 3 / 6, 0.0)
    P = 2 * w * (1 - delta) - 4 / 3 * (1 - delta ** 1.5) + k
    Q = 2 * w * (1 + delta) - 4 / 3 + 4 * delta + k
    return _out(P), _out(Q)


def eq32(delta, eps, w):
    """Eq. 32: working point v*/(omega R) with the transition between the steps,
    (1-eps) [4/3 (1 - delta^1.5) - 2w(1-delta)] / [4/3 - 4 delta - 2w(1+delta)].
    Valid for w >= 2 only (use ``working_point_ratio`` for 1 + sqrt(delta) <= w < 2)."""
    delta = _arr("delta", delta, 0, 1)
    eps = _arr("eps", eps)
    w = _arr("w", w, 0, np.inf, lo_open=True)
    if np.any(w < 2):
        raise ValueError("w must be >= 2 for Eq. 32 (the paper's assumption); "
                         "working_point_ratio covers 1 + sqrt(delta) <= w < 2")
    num = 4 / 3 * (1 - delta ** 1.5) - 2 * w * (1 - delta)
    den = 4 / 3 - 4 * delta - 2 * w * (1 + delta)
    return _out((1 - eps) * num / den)


def working_point_ratio(delta, eps, w):
    """Working point v*/(omega R) for w >= 1 + sqrt(delta): Eq. 32 for w >= 2, with the
    (2 - w)^3/6 correction below (see ``impulse_coefficients``)."""
    eps = _arr("eps", eps)
    P, Q = impulse_coefficients(delta, w)
    return _out((1 - eps) * np.asarray(P) / np.asarray(Q))


def invert_eq32_delta(ratio, eps, w):
    """delta in [0, 1] with eq32(delta, eps, w) = ratio (exact: a cubic in b = sqrt(delta)).

    eq32 = r (1-eps) with r = ratio/(1-eps) in [0, 1]:
    -4/3 b^3 + (2w + 4r + 2wr) b^2 + (4/3 - 2w - 4/3 r + 2wr) = 0; eq32 falls monotonically
    from 1-eps at delta = 0 to 0 at delta = 1, so the root in [0, 1] is unique."""
    ratio = _arr("ratio", ratio)
    eps = _arr("eps", eps)
    w = _arr("w", w, 2, np.inf)
    if np.any(eps == 1):
        raise ValueError("eps must differ from 1 (no creep: every delta gives v* = 0)")
    r = ratio / (1 - eps)
    if np.any((r < 0) | (r > 1)):
        raise ValueError("ratio must lie between 0 and 1 - eps (the reachable working points)")
    rb, wb = np.broadcast_arrays(r, w)
    out = np.empty(rb.shape)
    for idx in np.ndindex(rb.shape):
        rr, ww = rb[idx], wb[idx]
        roots = np.roots([-4 / 3, 2 * ww + 4 * rr + 2 * ww * rr, 0.0,
                          4 / 3 - 2 * ww - 4 / 3 * rr + 2 * ww * rr])
        real = roots[np.abs(roots.imag) < 1e-9].real
        ok = real[(real >= -1e-12) & (real <= 1 + 1e-12)]
        b = float(np.clip(ok[np.argmin(np.abs(ok - 0.5))] if ok.size else np.nan, 0, 1))
        # one Newton polish on the cubic for full precision
        f = -4 / 3 * b ** 3 + (2 * ww + 4 * rr + 2 * ww * rr) * b ** 2 + \
            (4 / 3 - 2 * ww - 4 / 3 * rr + 2 * ww * rr)
        fp = -4 * b ** 2 + 2 * (2 * ww + 4 * rr + 2 * ww * rr) * b
        if fp != 0:
            b = float(np.clip(b - f / fp, 0, 1))
        out[idx] = b * b
    return _out(out)


def invert_eq32_eps(ratio, delta, w):
    """eps with eq32(delta, eps, w) = ratio: eps = 1 - ratio / eq32(delta, 0, w)."""
    ratio = _arr("ratio", ratio)
    base = np.asarray(eq32(delta, 0.0, w))
    if np.any(base == 0):
        raise ValueError("delta must be < 1 (delta = 1 gives v* = 0 for every eps)")
    return _out(1 - ratio / base)


# ----------------------------------------------------------------------------- Cattaneo-Mindlin
def mindlin_ustar(mu, d, E_star, G_star):
    """Tangential displacement u* = mu E* d / G* [m] at which the whole contact slides."""
    mu = _arr("mu", mu, 0, np.inf, lo_open=True)
    d = _arr("d", d, 0)
    return _out(mu * _arr("E_star", E_star, 0, np.inf, lo_open=True) * d
                / _arr("G_star", G_star, 0, np.inf, lo_open=True))


def mindlin_force(u, mu, N, d, E_star, G_star):
    """Cattaneo-Mindlin: T = mu N [1 - (1 - |u|/u*)^(3/2)] sign(u) for |u| <= u*, mu N beyond."""
    u = _arr("u", u)
    N = _arr("N", N, 0)
    us = np.asarray(mindlin_ustar(mu, d, E_star, G_star))
    x = np.clip(np.abs(u) / us, 0.0, 1.0)
    return _out(np.sign(u) * np.asarray(mu) * N * (1 - (1 - x) ** 1.5))
