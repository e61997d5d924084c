"""The analytic reference module (rolling_env.physics.analytic) against known values and itself.

Tolerances: 5e-6 absolute for the paper's printed six-digit samples of Eq. 32, 1e-12..1e-10
for self-consistency (round trips, identities, which only rounding limits), 1e-5 relative
for limits taken at a large but finite argument, 1e-4 relative for a finite-difference slope,
0.1 % for material constants quoted to four digits.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from rolling_env.physics import analytic as an

# ----------------------------------------------------------------------------- materials
STEEL = dict(E1=210e9, nu1=0.3, E2=210e9, nu2=0.3)


def test_effective_moduli_steel():
    """Steel on steel: E* = E/(2(1-nu^2)) = 115.4 GPa, G*/E* = 2(1-nu)/(2-nu) = 0.8235."""
    E_star, G_star = an.effective_moduli(**STEEL)
    assert abs(E_star - 115.4e9) < 1e-3 * 115.4e9, f"E* = {E_star:.4g} Pa, expected 115.4 GPa"
    assert abs(G_star / E_star - 0.8235) < 1e-4, f"G*/E* = {G_star / E_star:.6f}"
    assert abs(G_star / E_star - an.g_over_e(0.3)) < 1e-12, "g_over_e disagrees with Eq. 1"


@pytest.mark.parametrize("nu", [0.0, 0.25, 0.3, 0.5])
def test_g_over_e_matches_eq1(nu):
    """g_over_e(nu) is Eq. 1 for two bodies of one material (any E)."""
    E_star, G_star = an.effective_moduli(70e9, nu, 70e9, nu)
    assert abs(G_star / E_star - an.g_over_e(nu)) < 1e-12, f"nu={nu}"


# ----------------------------------------------------------------------------- Hertz
@pytest.mark.parametrize("d", [0.0, 1e-9, 2.7e-7, 3e-6])
@pytest.mark.parametrize("R", [1e-4, 1e-3, 0.013])
def test_hertz_round_trip(d, R):
    """d -> N -> d recovers the indentation (relative 1e-12)."""
    E_star = 115.4e9
    back = an.hertz_indentation(an.hertz_force(d, R, E_star), R, E_star)
    assert abs(back - d) <= 1e-12 * d, f"d={d} R={R}: got {back}"


def test_hertz_broadcast_and_contact_radius():
    """Arrays broadcast; a^2 = R d; scalars give float."""
    d = np.array([1e-7, 2e-7, 4e-7])
    R = 1e-3
    a = an.contact_radius(d, R)
    assert isinstance(a, np.ndarray) and a.shape == (3,)
    assert np.allclose(a**2, R * d, rtol=1e-14, atol=0), f"a^2={a**2}"
    assert isinstance(an.contact_radius(1e-7, R), float)
    N = an.hertz_force(d[:, None], np.array([1e-3, 2e-3]), 115e9)
    assert N.shape == (3, 2)


def test_stiffness_and_natural_frequency():
    """omega_n^2 m = 2 a1 G*."""
    a1, G_star, m = 1.5e-5, 95e9, 2e-3
    k = an.tangential_stiffness(a1, G_star)
    assert abs(k - 2 * a1 * G_star) < 1e-12 * k
    wn = an.natural_frequency(a1, G_star, m)
    assert abs(wn**2 * m - k) < 1e-12 * k, f"omega_n={wn}"


# ----------------------------------------------------------------------------- working points
@pytest.mark.parametrize(
    "delta,eps,w,ref",
    [(0.93, 0.2, 2.2, 0.012537), (0.7, 0.1, 2.5, 0.085565), (0.5, 0.3, 5.0, 0.184893)],
)
def test_eq32_samples(delta, eps, w, ref):
    """Sample values of Eq. 32 (physics.md), six printed digits."""
    val = an.eq32(delta, eps, w)
    assert abs(val - ref) < 5e-6, f"eq32({delta}, {eps}, {w}) = {val:.7f}, expected {ref}"


@pytest.mark.parametrize("delta", [0.0, 0.3, 0.7, 0.93, 1.0])
@pytest.mark.parametrize("eps", [-0.5, 0.2, 0.9, 1.4])
def test_eq32_tends_to_eq29(delta, eps):
    """Large amplitude: Eq. 32 -> Eq. 29 (w = 1e7, relative 1e-5)."""
    e32, e29 = an.eq32(delta, eps, 1e7), an.eq29(delta, eps)
    assert abs(e32 - e29) <= 1e-5 * abs(e29) + 1e-15, f"eq32={e32} eq29={e29}"


@pytest.mark.parametrize("eps", [-0.5, 0.0, 0.3, 0.99, 2.0])
@pytest.mark.parametrize("w", [2.0, 2.2, 5.0, 50.0])
def test_eq32_limits(eps, w):
    """delta = 1 (equal forces): no drive; delta = 0 (no back contact): runner follows."""
    assert abs(an.eq32(1.0, eps, w)) < 1e-15, f"eq32(1, {eps}, {w}) = {an.eq32(1.0, eps, w)}"
    e0 = an.eq32(0.0, eps, w)
    assert abs(e0 - (1 - eps)) < 1e-14, f"eq32(0, {eps}, {w}) = {e0}, expected {1 - eps}"


@pytest.mark.parametrize("w", [2.0, 2.2, 3.0, 10.0, 1e4])
def test_eq32_monotone_in_delta(w):
    """For w >= 2 and eps < 1, Eq. 32 falls strictly with delta on [0, 1] (the inversion's
    uniqueness rests on this)."""
    delta = np.linspace(0.0, 1.0, 2001)
    v = an.eq32(delta, 0.2, w)
    assert np.all(np.diff(v) < 0), f"w={w}: not strictly decreasing"


def test_steady_forces_vanish_sum_at_eq29():
    """Eqs. 27-28: at the Eq. 29 working point the steady forces cancel, T1 + T2 = 0."""
    delta, eps, a1, G_star = 0.7, 0.1, 1.5e-5, 95e9
    T1, T2 = an.steady_forces(delta, eps, an.eq29(delta, eps), a1, G_star)
    scale = 2 * G_star * a1**2
    assert abs(T1 + T2) < 1e-14 * scale, f"T1={T1} T2={T2}"
    assert abs(T1 - scale * (1 - eps - an.eq29(delta, eps))) < 1e-12 * scale


@pytest.mark.parametrize("delta,w", list(itertools.product([0.0, 0.3, 0.93, 1.0], [2.0, 2.2, 7.0])))
def test_impulse_coefficients_give_eq32(delta, w):
    """For w >= 2: (1 - eps) P/Q = Eq. 32 = working_point_ratio, and I(eq32) = 0."""
    eps = 0.15
    P, Q = an.impulse_coefficients(delta, w)
    ref = an.eq32(delta, eps, w)
    assert abs((1 - eps) * P / Q - ref) < 1e-14, f"P/Q gives {(1 - eps) * P / Q}, eq32 {ref}"
    assert abs(an.working_point_ratio(delta, eps, w) - ref) < 1e-14
    assert abs((1 - eps) * P - ref * Q) < 1e-13 * abs(Q), "impulse nonzero at Eq. 32"


@pytest.mark.parametrize("delta", [0.0, 0.2, 0.5, 0.9])
def test_working_point_continuous_at_w2(delta):
    """The (2 - w)^3/6 branch joins Eq. 32 at w = 2 without a jump or a kink: the one-sided
    differences agree to O(h^2), and below w = 2 the correction differs from Eq. 32's formula
    (P, Q without k) by O(h^3)."""
    eps, h = 0.1, 1e-3
    below, at, above = (an.working_point_ratio(delta, eps, w) for w in (2 - h, 2.0, 2 + h))
    assert abs(at - an.eq32(delta, eps, 2.0)) < 1e-15, "w = 2 must give Eq. 32"
    assert abs(below - at) < 10 * h and abs(above - at) < 10 * h, f"{below} {at} {above}"
    assert abs(below - 2 * at + above) < 10 * h**2, f"kink at w = 2: {below} {at} {above}"
    w = 2 - h
    plain = (
        (1 - eps)
        * (2 * w * (1 - delta) - 4 / 3 * (1 - delta**1.5))
        / (2 * w * (1 + delta) - 4 / 3 + 4 * delta)
    )
    assert abs(below - plain) < h**3, f"correction {below - plain:.3g} is not O(h^3)"


def test_working_point_ratio_broadcast():
    """Arrays over both branches at once."""
    w = np.array([1.9, 2.0, 3.0])
    v = an.working_point_ratio(0.5, 0.1, w)
    assert v.shape == (3,) and np.all(np.isfinite(v))
    assert abs(v[2] - an.eq32(0.5, 0.1, 3.0)) < 1e-15


# ----------------------------------------------------------------------------- inversions
GRID = list(
    itertools.product(np.linspace(0.05, 1.0, 9), [-0.5, 0.0, 0.4, 0.9], [2.0, 2.2, 3.7, 11.0, 50.0])
)


@pytest.mark.parametrize("delta,eps,w", GRID)
def test_invert_eq32_delta_round_trip(delta, eps, w):
    """eq32 -> invert_eq32_delta recovers delta (1e-10) on a grid of (delta, eps, w)."""
    got = an.invert_eq32_delta(an.eq32(delta, eps, w), eps, w)
    assert abs(got - delta) < 1e-10, f"delta={delta} eps={eps} w={w}: got {got}"


def test_invert_eq32_delta_vectorised_and_edges():
    """Array input, the reachable ends (ratio 0 -> delta 1, ratio 1 - eps -> delta 0) and
    reverse creep (eps > 1, negative ratio)."""
    delta = np.array([[0.1, 0.5], [0.8, 0.99]])
    got = an.invert_eq32_delta(an.eq32(delta, 0.3, 2.5), 0.3, 2.5)
    assert got.shape == (2, 2) and np.max(np.abs(got - delta)) < 1e-10, f"{got}"
    assert abs(an.invert_eq32_delta(0.0, 0.3, 2.5) - 1.0) < 1e-12
    assert abs(an.invert_eq32_delta(0.7, 0.3, 2.5)) < 1e-12
    assert abs(an.invert_eq32_delta(an.eq32(0.6, 1.5, 4.0), 1.5, 4.0) - 0.6) < 1e-10


@pytest.mark.parametrize("w", [1e3, 1e8, 1e12, an.W_MAX])
def test_eq32_and_inverse_at_large_w(w):
    """Up to W_MAX: Eq. 32 tends to its w -> inf limit (1 - eps)(1 - delta)/(1 + delta) = Eq. 29
    without overflow, and the inversion still recovers delta (1e-10; it once returned 0 for
    w >= 1e25, where the cubic term vanished next to the w-sized ones)."""
    for delta in (0.05, 0.5, 0.9):
        v = an.eq32(delta, 0.1, w)
        assert abs(v - an.eq29(delta, 0.1)) <= 2.0 / w, (
            f"w={w}: {v} vs Eq. 29 {an.eq29(delta, 0.1)}"
        )
        assert abs(an.invert_eq32_delta(v, 0.1, w) - delta) < 1e-10, f"w={w}, delta={delta}"
        assert an.working_point_ratio(delta, 0.1, w) == pytest.approx(v, rel=1e-13)


@pytest.mark.parametrize("delta,eps,w", [c for c in GRID if c[0] < 1])
def test_invert_eq32_eps_round_trip(delta, eps, w):
    """eq32 -> invert_eq32_eps recovers eps (delta < 1 only: at delta = 1 eps is free)."""
    got = an.invert_eq32_eps(an.eq32(delta, eps, w), delta, w)
    assert abs(got - eps) < 1e-10, f"delta={delta} eps={eps} w={w}: got {got}"


# ----------------------------------------------------------------------------- Cattaneo-Mindlin
R, E_STAR, G_STAR, MU, D = 1e-3, 115.4e9, 95e9, 0.2, 2e-7


def test_mindlin_ends():
    """T(0) = 0, T(u*) = mu N = T beyond u*, odd in u."""
    N = an.hertz_force(D, R, E_STAR)
    us = an.mindlin_ustar(MU, D, E_STAR, G_STAR)
    assert abs(us - MU * E_STAR * D / G_STAR) < 1e-12 * us
    T = lambda u: an.mindlin_force(u, MU, N, D, E_STAR, G_STAR)  # noqa: E731
    assert T(0.0) == 0.0, f"T(0) = {T(0.0)}"
    assert abs(T(us) - MU * N) < 1e-12 * MU * N, f"T(u*) = {T(us)}, mu N = {MU * N}"
    assert abs(T(3 * us) - MU * N) < 1e-12 * MU * N, "full sliding must saturate at mu N"
    u = np.linspace(-2 * us, 2 * us, 41)
    assert np.allclose(T(-u), -T(u), rtol=0, atol=1e-15 * MU * N), "not odd in u"
    assert np.all(np.diff(T(u)) >= 0), "not monotone"


def test_mindlin_initial_stiffness_is_2aG():
    """Physics: the initial slope of the Mindlin law, 3/2 mu N/u*, equals the stuck-contact
    stiffness 2 a G* with a = sqrt(R d), N = 4/3 E* sqrt(R) d^1.5 (finite difference, 1e-4)."""
    N = an.hertz_force(D, R, E_STAR)
    us = an.mindlin_ustar(MU, D, E_STAR, G_STAR)
    h = 1e-6 * us
    slope = (
        an.mindlin_force(h, MU, N, D, E_STAR, G_STAR)
        - an.mindlin_force(-h, MU, N, D, E_STAR, G_STAR)
    ) / (2 * h)
    k = an.tangential_stiffness(an.contact_radius(D, R), G_STAR)
    assert abs(slope - k) < 1e-4 * k, f"slope {slope:.6g} vs 2 a G* {k:.6g}"


def test_mindlin_no_contact():
    """d = 0 (no contact, N = 0): u* = 0 and T = 0 without NaN."""
    assert an.mindlin_force(1e-9, MU, 0.0, 0.0, E_STAR, G_STAR) == 0.0


# ----------------------------------------------------------------------------- bad input
BAD = [
    (an.eq32, (1.3, 0.1, 2.5), "delta"),
    (an.eq32, (-0.1, 0.1, 2.5), "delta"),
    (an.eq32, (math.nan, 0.1, 2.5), "delta"),
    (an.eq32, (0.5, math.nan, 2.5), "eps"),
    (an.eq32, (0.5, math.inf, 2.5), "eps"),
    (an.eq32, (0.5, 0.1, 1.9), "working_point_ratio"),
    (an.eq32, (0.5, 0.1, -1.0), "w"),
    (an.eq32, (0.5, 0.1, 1e308), "w"),
    (an.working_point_ratio, (0.5, 0.1, math.inf), "w"),
    (an.invert_eq32_delta, (0.05, 0.1, 1e25), "w"),
    (an.hertz_indentation, (1e308, 1e-300, 1e-300), "indentation d overflows"),
    (an.hertz_force, (1e300, 1e300, 1e300), "normal force N overflows"),
    (an.eq32, (np.array([0.5, np.nan]), 0.1, 2.5), "delta"),
    (an.eq29, (2.0, 0.1), "delta"),
    (an.working_point_ratio, (0.81, 0.1, 1.85), "w"),
    (an.impulse_coefficients, (0.5, math.nan), "w"),
    (an.invert_eq32_delta, (0.95, 0.1, 2.5), "ratio"),
    (an.invert_eq32_delta, (-0.01, 0.1, 2.5), "ratio"),
    (an.invert_eq32_delta, (0.1, 1.0, 2.5), "eps"),
    (an.invert_eq32_delta, (0.1, 0.1, 1.5), "w"),
    (an.invert_eq32_delta, (math.nan, 0.1, 2.5), "ratio"),
    (an.invert_eq32_eps, (0.1, 1.0, 2.5), "delta"),
    (an.effective_moduli, (210e9, 0.6, 210e9, 0.3), "nu1"),
    (an.effective_moduli, (210e9, 0.3, 0.0, 0.3), "E2"),
    (an.g_over_e, (math.nan,), "nu"),
    (an.hertz_indentation, (-1.0, 1e-3, 1e11), "N"),
    (an.hertz_indentation, (1.0, 0.0, 1e11), "R"),
    (an.hertz_force, (1e-7, 1e-3, math.inf), "E_star"),
    (an.contact_radius, (-1e-7, 1e-3), "d"),
    (an.steady_forces, (0.5, 0.1, math.nan, 1e-5, 9e10), "vstar_ratio"),
    (an.natural_frequency, (1e-5, 9e10, 0.0), "m"),
    (an.mindlin_ustar, (math.inf, 1e-7, 1e11, 9e10), "mu"),
    (an.mindlin_force, (1e-9, 0.0, 1.0, 1e-7, 1e11, 9e10), "mu"),
    (an.mindlin_force, (math.nan, 0.2, 1.0, 1e-7, 1e11, 9e10), "u"),
    # finite input whose result leaves the float range: named, not returned as inf
    (an.steady_forces, (0.5, 0.1, 0.1, 1e200, 1e200), "T1 overflows"),
    (an.invert_eq32_eps, (1e308, 0.7, 2.5), "eps overflows"),
    (an.tangential_stiffness, (1e300, 1e300), "stiffness 2 a G\\* overflows"),
    (an.natural_frequency, (1e-3, 1e10, 5e-324), "omega_n overflows"),
    (an.mindlin_ustar, (1e300, 1e10, 1e300, 1e-300), "u\\* overflows"),
    (an.mindlin_force, (1.0, 1e300, 1e300, 1e-20, 1.0, 1.0), "tangential force T overflows"),
    (an.contact_radius, (1e300, 1e300), "contact radius a overflows"),
    (an.effective_moduli, (5e-324, 0.3, 1e9, 0.3), "E_star leaves the float range"),
    (an.effective_moduli, (1e308, 0.0, 1e308, 0.0), "G_star leaves the float range"),
]


@pytest.mark.parametrize(
    "fn,args,name", BAD, ids=[f"{f.__name__}-{n}-{i}" for i, (f, _, n) in enumerate(BAD)]
)
def test_bad_input_names_parameter(fn, args, name):
    """Out-of-range, NaN and inf input raise ValueError naming the parameter."""
    with pytest.raises(ValueError, match=name):
        fn(*args)


def test_error_message_gives_range():
    """The message states the allowed range and the offending value."""
    with pytest.raises(ValueError, match=r"delta must be finite and in \[0, 1\], got 1.3"):
        an.eq32(1.3, 0.1, 2.5)
    with pytest.raises(ValueError, match=r"ratio must be in the reachable range \[0, 0.9\]"):
        an.invert_eq32_delta(0.95, 0.1, 2.5)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: an.eq32("a", 0.1, 2.5), "delta"),
        (lambda: an.eq32(0.5, None, 2.5), "eps"),
        (lambda: an.eq29(0.5, [0.1, "x"]), "eps"),
        (lambda: an.eq32(True, 0.1, 2.5), "delta"),
        (lambda: an.hertz_force(1e-7, 1e-3, 1 + 2j), "E_star"),
        (lambda: an.working_point_ratio(0.5, 0.1, [[2.5], [2.5, 3.0]]), "w"),
    ],
)
def test_non_numeric_input_names_the_parameter(call, name):
    """Strings, None, booleans, complex numbers and ragged lists are a ValueError naming the
    parameter (a string gave numpy's 'could not convert string to float', which names none)."""
    with pytest.raises(ValueError, match=f"^{name} must be a real number"):
        call()


@pytest.mark.parametrize("eps", [-0.5, 0.1, 0.9, 1.7])
@pytest.mark.parametrize("w", [1.0, 1.5, 2.0, 5.0])
def test_delta_zero_gives_one_minus_eps_everywhere(eps, w):
    """delta = 0 (no back-step contact) is inside every working-point formula: Eq. 29, Eq. 32
    and the w < 2 corrected ratio all give 1 - eps to 1e-14 (the runner follows the sphere);
    inverting Eq. 32 at ratio 1 - eps gives delta = 0 back."""
    assert abs(an.eq29(0.0, eps) - (1 - eps)) < 1e-14
    assert abs(an.working_point_ratio(0.0, eps, w) - (1 - eps)) < 1e-14
    if w >= 2:
        assert abs(an.eq32(0.0, eps, w) - (1 - eps)) < 1e-14
        if eps != 1:
            assert an.invert_eq32_delta(1 - eps, eps, w) < 1e-12


@pytest.mark.parametrize(
    "call",
    [
        lambda: an.eq32([0.5, 0.6], [0.1, 0.2, 0.3], 3.0),
        lambda: an.steady_forces(0.5, [0.1, 0.2], [0.0, 0.1, 0.2], 1e-5, 9e10),
        lambda: an.mindlin_force(np.zeros(4), 0.2, np.ones(3), 1e-7, 1e11, 9e10),
    ],
)
def test_shapes_that_do_not_broadcast_are_named(call):
    """numpy's "operands could not be broadcast" names no parameter: the error names the
    function and the shapes of the parameters given as arrays."""
    with pytest.raises(
        ValueError,
        match=r"the parameters must broadcast together .*got shapes "
        r"\w+ \(\d,\), \w+ \(\d,\)$",
    ):
        call()


def test_broadcasting_parameters_still_work():
    got = an.eq32(np.array([[0.5], [0.7]]), np.array([0.1, 0.2, 0.3]), 2.5)
    assert got.shape == (2, 3)
    assert got[1, 0] == pytest.approx(an.eq32(0.7, 0.1, 2.5), rel=1e-15)


@pytest.mark.parametrize("as_type", [float, int, np.float64, np.float32, np.int64, np.asarray])
def test_scalar_types_give_the_array_result(as_type):
    """Scalar calls skip the broadcast check (a fast path for the common case): every scalar
    type, and a 0-d array, gives the value of the 1-element array call to 1e-15 as a float;
    out-of-range scalars still raise naming the parameter."""
    args = (as_type(0), as_type(1), as_type(3))  # delta = 0, eps = 1 (no creep), w = 3
    want = float(an.eq32(np.array([0.0]), np.array([1.0]), np.array([3.0]))[0])
    got = an.eq32(*args)
    assert type(got) is float, f"eq32 of {as_type.__name__} scalars returned {type(got)}"
    assert abs(got - want) <= 1e-15, f"eq32 of {as_type.__name__} scalars: {got} vs {want}"
    got = an.hertz_force(as_type(1), as_type(4), as_type(3))  # 4/3 E* sqrt(R) d^1.5 = 8
    assert type(got) is float and abs(got - 8.0) <= 8e-15, f"hertz_force: {got!r}, not 8"
    with pytest.raises(ValueError, match=r"^w must be finite and in \(0, 1e\+15\]"):
        an.eq32(as_type(0), as_type(1), as_type(-3))


def test_mindlin_force_without_indentation_is_full_sliding():
    """d = 0 gives u* = 0: every displacement is beyond it, T = mu N sign(u) (the docstring's
    law; it returned 0), and T(0) = 0."""
    for u, want in ((1e-6, 0.3), (-1e-9, -0.3), (0.0, 0.0)):
        got = an.mindlin_force(u, 0.3, 1.0, 0.0, 1e10, 1e10)
        assert got == want, f"mindlin_force(u={u}, d=0) = {got}, want {want}"
