"""Analytic reference results of the drive (paper Eqs. 1-3, 27-29, 32; Cattaneo-Mindlin).

Names follow the paper: sphere radius R [m], effective moduli E_star, G_star [Pa], friction
coefficient mu, delta = d2/d1 (back/forth indentation), eps = v/(omega R) (translation over
rolling velocity), w = W/a1 (rolling amplitude over the forth contact radius).  Every function
takes scalars or numpy arrays (broadcast), returns a float for scalar input and an ndarray
otherwise, and rejects out-of-range input (NaN and inf included) with a ``ValueError`` that
names the parameter and its allowed range.
"""

from __future__ import annotations

import math

import numpy as np

from rolling_env.validation import as_real_array

_TOL = 1e-12  # rounding slack when a target ratio sits on the edge of its reachable range
W_MAX = 1e15  # largest rolling amplitude w = W/a1 taken (far beyond any drive; bounded so that
# the impulse coefficients ~ w stay finite)


# ----------------------------------------------------------------------------- validation
def _arr(name, x, lo=-np.inf, hi=np.inf, lo_open=False, hi_open=False):
    """``x`` as a float64 array, checked to be finite and in the interval [lo, hi]
    (ends open where asked); strings, booleans, complex numbers and other non-real input are
    a ValueError naming the parameter."""
    a = as_real_array(name, x)
    bad = ~np.isfinite(a) | (a < lo) | (a > hi)
    if lo_open:
        bad |= a == lo
    if hi_open:
        bad |= a == hi
    if np.any(bad):
        rng = f"{'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open or hi == np.inf else ']'}"
        what = "finite" if np.isinf(lo) and np.isinf(hi) else f"finite and in {rng}"
        raise ValueError(f"{name} must be {what}, got {_first(a, bad)!r}")
    return a


def _first(x, mask):
    """The first element of ``x`` (broadcast to ``mask``) where ``mask`` holds, as a float."""
    return float(np.broadcast_to(x, np.shape(mask))[mask].ravel()[0])


def _pos(name, x):
    """``x`` checked to be in (0, inf)."""
    return _arr(name, x, 0.0, np.inf, lo_open=True)


def _out(a):
    return float(a) if np.ndim(a) == 0 else a


def _w(w, lo=0.0, lo_open=True):
    """The rolling amplitude w = W/a1, checked to be in (0, W_MAX] (or [lo, W_MAX])."""
    return _arr("w", w, lo, W_MAX, lo_open=lo_open)


def _finite(name, a, positive=False):
    """A result that overflowed for finite input is a ValueError, not an inf; with
    ``positive`` also one that underflowed to 0 (or below)."""
    if np.ndim(a) == 0:  # scalar input: math.isfinite is ~10x cheaper than the array test
        a = float(a)
        ok = math.isfinite(a) and (a > 0 or not positive)
    else:
        ok = np.all(np.isfinite(a)) and (not positive or np.all(a > 0))
    if ok:
        return _out(a)
    if positive:
        raise ValueError(
            f"{name} leaves the float range for this input (inputs too large or too small)"
        )
    raise ValueError(f"{name} overflows the float range for this input (inputs too large)")


# scalars that always broadcast: _together skips its shape check for calls made of them only
_SCALAR_TYPES = (float, int, np.float64)


def _together(fn):
    """The parameters of ``fn`` must broadcast together (numpy's rules): a ValueError naming
    them and their shapes, instead of numpy's "operands could not be broadcast" from inside
    the formula."""
    import functools
    import inspect

    names = list(inspect.signature(fn).parameters)

    @functools.wraps(fn)
    def checked(*args, **kwargs):
        if not kwargs and all(type(v) in _SCALAR_TYPES for v in args):
            return fn(*args)  # scalars broadcast with anything (their own checks follow)
        shapes = {}
        for name, value in [*zip(names, args), *kwargs.items()]:
            try:
                shapes[name] = np.shape(value)
            except ValueError:  # ragged: the parameter's own check names it
                continue
        try:
            np.broadcast_shapes(*shapes.values())
        except ValueError:
            given = ", ".join(f"{k} {v}" for k, v in shapes.items() if v != ())
            raise ValueError(
                f"{fn.__name__}: the parameters must broadcast together (numpy's "
                f"rules), got shapes {given}"
            ) from None
        return fn(*args, **kwargs)

    return checked


# ----------------------------------------------------------------------------- materials
@_together
def effective_moduli(E1, nu1, E2, nu2):
    """Eq. 1: (E_star, G_star) [Pa] of two elastic bodies, Young moduli E1, E2 > 0 [Pa] and
    Poisson ratios nu1, nu2 in [0, 0.5]:
    1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2,  1/G* = (2-nu1)/(4 G1) + (2-nu2)/(4 G2),
    G_i = E_i / (2 (1 + nu_i))."""
    E1, E2 = _pos("E1", E1), _pos("E2", E2)
    nu1, nu2 = _arr("nu1", nu1, 0, 0.5), _arr("nu2", nu2, 0, 0.5)
    with np.errstate(over="ignore", divide="ignore"):
        G1, G2 = E1 / (2 * (1 + nu1)), E2 / (2 * (1 + nu2))
        E_star = 1 / ((1 - nu1**2) / E1 + (1 - nu2**2) / E2)
        G_star = 1 / ((2 - nu1) / (4 * G1) + (2 - nu2) / (4 * G2))
    return _finite("E_star", E_star, positive=True), _finite("G_star", G_star, positive=True)


def g_over_e(nu):
    """G*/E* = 2(1-nu)/(2-nu) for two bodies of one material, nu in [0, 0.5]
    (0.8235 for nu = 0.3)."""
    nu = _arr("nu", nu, 0, 0.5)
    return _out(2 * (1 - nu) / (2 - nu))


# ----------------------------------------------------------------------------- Hertz
@_together
def hertz_indentation(N, R, E_star):
    """Eq. 2: indentation d [m] = (3 N / (4 E* sqrt(R)))^(2/3); N >= 0 [N], R > 0 [m],
    E_star > 0 [Pa]."""
    N = _arr("N", N, 0)
    R, E_star = _pos("R", R), _pos("E_star", E_star)
    with np.errstate(over="ignore"):
        d = (3 * N / (4 * E_star * np.sqrt(R))) ** (2 / 3)
    return _finite("the indentation d", d)


@_together
def hertz_force(d, R, E_star):
    """Normal force N [N] = 4/3 E* sqrt(R) d^(3/2); d >= 0 [m], R > 0 [m], E_star > 0 [Pa]."""
    d = _arr("d", d, 0)
    R, E_star = _pos("R", R), _pos("E_star", E_star)
    with np.errstate(over="ignore"):
        N = 4 / 3 * E_star * np.sqrt(R) * d**1.5
    return _finite("the normal force N", N)


@_together
def contact_radius(d, R):
    """Eq. 3: contact radius a [m] = sqrt(R d); d >= 0 [m], R > 0 [m]."""
    R, d = _pos("R", R), _arr("d", d, 0)
    with np.errstate(over="ignore"):
        return _finite("the contact radius a", np.sqrt(R * d))


@_together
def tangential_stiffness(a, G_star):
    """Stiffness 2 a G* [N/m] of a stuck contact of radius a >= 0 [m], G_star > 0 [Pa]."""
    a, G_star = _arr("a", a, 0), _pos("G_star", G_star)
    with np.errstate(over="ignore"):
        return _finite("the stiffness 2 a G*", 2 * a * G_star)


@_together
def natural_frequency(a1, G_star, m):
    """omega_n = sqrt(2 a1 G* / m) [rad/s] of a runner of mass m > 0 [kg] on the stuck
    contact of radius a1 [m]."""
    k = tangential_stiffness(a1, G_star)
    m = _pos("m", m)
    with np.errstate(over="ignore"):
        return _finite("omega_n", np.sqrt(k / m))


# ----------------------------------------------------------------------------- working points
@_together
def steady_forces(delta, eps, vstar_ratio, a1, G_star):
    """Eqs. 27-28: steady rolling forces [N] on the runner in the forth and back steps,
    T1 = 2 G* a1^2 (1 - eps - V),  T2 = 2 G* a2^2 (-1 + eps - V),  a2^2 = delta a1^2,
    with V = vstar_ratio = v*/(omega R), a1 >= 0 [m], G_star > 0 [Pa], delta in [0, 1]."""
    delta, eps = _arr("delta", delta, 0, 1), _arr("eps", eps)
    V = _arr("vstar_ratio", vstar_ratio)
    G_star, a1 = _pos("G_star", G_star), _arr("a1", a1, 0)
    with np.errstate(over="ignore", invalid="ignore"):  # an overflow is _finite's error
        scale = 2 * G_star * a1**2
        T1, T2 = scale * (1 - eps - V), scale * delta * (-1 + eps - V)
    return _finite("T1", T1), _finite("T2", T2)


@_together
def eq29(delta, eps):
    """Eq. 29 (= Eq. 11), steady rolling (large amplitude):
    v*/(omega R) = (1 - eps)(1 - delta)/(1 + delta); delta in [0, 1], eps finite."""
    delta, eps = _arr("delta", delta, 0, 1), _arr("eps", eps)
    return _finite("Eq. 29's v*/(omega R)", (1 - eps) * (1 - delta) / (1 + delta))


@_together
def impulse_coefficients(delta, w):
    """(P, Q) of the period impulse I = (1 - eps) P - V Q of the runner force, V = v*/(omega R),
    in units of G* a1^2 * (a1 / (omega R)) [N s]; delta in [0, 1], 1 + sqrt(delta) <= w <= W_MAX.

    Derivation (physics.md kinematics, lengths in a1, times in a1/(omega R)): every spring in
    contact creeps at s1 = (1 - eps) - V in the forth step and s2 = -(1 - eps) - V in the back
    step, so I = s1 C1 + s2 C2 summed over the forth and back steps, where C1, C2 collect the
    spring-time integrals of the contact (including the forth-step deflection the springs still
    carry into the back step).  For w >= 2 every spring is released once per step and
        C1 = 2 w - 4/3 + 2 delta + 2/3 delta^1.5,   C2 = 2 delta w + 2 delta - 2/3 delta^1.5,
    hence  P = C1 - C2 = 2 w (1 - delta) - 4/3 (1 - delta^1.5)
    and    Q = C1 + C2 = 2 w (1 + delta) - 4/3 + 4 delta;  I = 0 gives Eq. 32 = (1-eps) P/Q.

    For 1 + sqrt(delta) <= w < 2 not every forth-step spring is released before the step
    reverses and C1 gains k = (2 - w)^3 / 6, so P and Q both gain k.  This branch is taken from
    physics.md, not from the paper; it is checked against the simulation in
    tests/physics/test_physics.py.  Below w = 1 + sqrt(delta) some springs never release and the
    formula does not apply: ValueError.
    """
    delta, w = _arr("delta", delta, 0, 1), _w(w)
    low = w < 1 + np.sqrt(delta)
    if np.any(low):
        raise ValueError(
            f"w must be >= 1 + sqrt(delta), got w = {_first(w, low)!r} at "
            f"delta = {_first(delta, low)!r}: below, some springs never release "
            "and the formula does not apply"
        )
    k = np.maximum(2 - w, 0.0) ** 3 / 6
    P = 2 * w * (1 - delta) - 4 / 3 * (1 - delta**1.5) + k
    Q = 2 * w * (1 + delta) - 4 / 3 + 4 * delta + k
    return _out(P), _out(Q)


@_together
def eq32(delta, eps, w):
    """Eq. 32: working point v*/(omega R) with the transition between the steps,
    (1 - eps) [4/3 (1 - delta^1.5) - 2 w (1 - delta)] / [4/3 - 4 delta - 2 w (1 + delta)];
    delta in [0, 1] (delta = 0 gives 1 - eps, delta = 1 gives 0), eps finite (eps > 1 is
    reverse creep), 2 <= w <= W_MAX only: use ``working_point_ratio`` for
    1 + sqrt(delta) <= w < 2."""
    delta, eps, w = _arr("delta", delta, 0, 1), _arr("eps", eps), _w(w)
    if np.any(w < 2):
        raise ValueError(
            f"w must be >= 2 for Eq. 32 (the paper's assumption), got "
            f"{_first(w, w < 2)!r}; working_point_ratio covers "
            "1 + sqrt(delta) <= w < 2"
        )
    num = 4 / 3 * (1 - delta**1.5) / w - 2 * (1 - delta)  # both over w: no overflow
    den = (4 / 3 - 4 * delta) / w - 2 * (1 + delta)
    return _finite("Eq. 32's v*/(omega R)", (1 - eps) * num / den)


@_together
def working_point_ratio(delta, eps, w):
    """Working point v*/(omega R) = (1 - eps) P/Q (zero period impulse) for
    w >= 1 + sqrt(delta): equal to Eq. 32 for w >= 2, with the (2 - w)^3/6 correction of
    physics.md below (see ``impulse_coefficients``; checked against simulation in
    tests/physics/test_physics.py)."""
    eps = _arr("eps", eps)
    P, Q = impulse_coefficients(delta, w)
    w = np.asarray(w, dtype=np.float64)
    return _finite(
        "the working point v*/(omega R)", (1 - eps) * (np.asarray(P) / w) / (np.asarray(Q) / w)
    )


def _cubic_root_b(r, w):
    """b = sqrt(delta) in [0, 1] with Eq. 32 = r (1 - eps), r in [0, 1], w >= 2.

    num(b) = r den(b) reads -4/3 b^3 + C2 b^2 + C0 = 0 with C2 = 2w + 4r + 2wr and
    C0 = (4/3 - 2w)(1 - r); f(0) <= 0 <= f(1) = r (8/3 + 4w) and f'(b) = b (2 C2 - 4 b) > 0
    on (0, 1] for w >= 2, so the root in [0, 1] is unique (Eq. 32 is monotone in delta).
    Solved with every coefficient divided by w (a large w would swamp the cubic term)."""
    c3, c2, c0 = -4 / 3 / w, 2 + (4 * r) / w + 2 * r, (4 / 3 / w - 2) * (1 - r)
    roots = np.roots([c3, c2, 0.0, c0])
    real = roots.real[np.abs(roots.imag) <= 1e-7 * (1 + np.abs(roots))]
    b = float(np.clip(np.max(real[real <= 1 + 1e-7], initial=0.0), 0.0, 1.0))
    for _ in range(2):  # Newton polish to full precision (the root is simple for r < 1)
        fp = b * (2 * c2 + 3 * c3 * b)
        if fp > 0:
            b = float(np.clip(b - (c3 * b**3 + c2 * b**2 + c0) / fp, 0.0, 1.0))
    return b


@_together
def invert_eq32_delta(ratio, eps, w):
    """delta in [0, 1] with eq32(delta, eps, w) = ratio (= v*/(omega R)), solved exactly as a
    cubic in b = sqrt(delta) (see ``_cubic_root_b``); eps finite and != 1, w >= 2.  ``ratio``
    must lie in the reachable range [0, 1 - eps] (for eps > 1: [1 - eps, 0])."""
    ratio, eps, w = _arr("ratio", ratio), _arr("eps", eps), _w(w, 2, False)
    if np.any(eps == 1):
        raise ValueError("eps must differ from 1 (no creep: every delta gives v* = 0)")
    r = ratio / (1 - eps)
    bad = (r < -_TOL) | (r > 1 + _TOL)
    if np.any(bad):
        e = _first(eps, bad)
        lo, hi = sorted((0.0, 1 - e))
        raise ValueError(
            f"ratio must be in the reachable range [{lo:g}, {hi:g}] (eps = {e!r}), "
            f"got {_first(ratio, bad)!r}"
        )
    rb, wb = np.broadcast_arrays(np.clip(r, 0.0, 1.0), w)
    b = np.array([_cubic_root_b(rr, ww) for rr, ww in zip(rb.ravel(), wb.ravel())])
    return _out((b**2).reshape(rb.shape))


@_together
def invert_eq32_eps(ratio, delta, w):
    """eps with eq32(delta, eps, w) = ratio: eps = 1 - ratio / eq32(delta, 0, w);
    ratio finite, delta in [0, 1) (at delta = 1 every eps gives 0), w >= 2."""
    ratio = _arr("ratio", ratio)
    base = np.asarray(eq32(delta, 0.0, w))
    if np.any(base == 0):
        raise ValueError("delta must be in [0, 1) (delta = 1 gives v* = 0 for every eps)")
    with np.errstate(over="ignore"):  # an overflow is _finite's error
        eps = 1 - ratio / base
    return _finite("eps", eps)


# ----------------------------------------------------------------------------- Cattaneo-Mindlin
@_together
def mindlin_ustar(mu, d, E_star, G_star):
    """Tangential displacement u* = mu E* d / G* [m] at which the whole contact slides;
    mu in (0, inf), d >= 0 [m], E_star, G_star > 0 [Pa]."""
    mu, d = _pos("mu", mu), _arr("d", d, 0)
    E_star, G_star = _pos("E_star", E_star), _pos("G_star", G_star)
    with np.errstate(over="ignore"):
        return _finite("u*", mu * E_star * d / G_star)


@_together
def mindlin_force(u, mu, N, d, E_star, G_star):
    """Cattaneo-Mindlin tangential force [N] of a Hertz contact (normal force N >= 0 [N],
    indentation d [m]) displaced by u [m] without rolling:
    T = mu N [1 - (1 - |u|/u*)^(3/2)] sign(u) for |u| <= u*, mu N sign(u) beyond (odd in u).
    Its initial slope 3/2 mu N/u* equals the stuck stiffness 2 a G*, a = sqrt(R d), when
    N = hertz_force(d, R, E_star)."""
    u, N = _arr("u", u), _arr("N", N, 0)
    us = np.asarray(mindlin_ustar(mu, d, E_star, G_star))
    # |u|/u* clipped to [0, 1]; u* = 0 (d = 0): every displacement is beyond it
    x = np.where(us > 0, np.minimum(np.abs(u), us) / np.where(us > 0, us, 1.0), 1.0)
    with np.errstate(over="ignore", invalid="ignore"):
        return _finite(
            "the tangential force T", np.sign(u) * np.asarray(mu) * N * (1 - (1 - x) ** 1.5)
        )
