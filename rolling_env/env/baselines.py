"""Baseline controllers from the paper's working-point formula (Eq. 32).

Both drive the paper's square wave: the patch oscillates between -W/2 and +W/2 (centred on
the stroke, starting with a quarter period from 0 to +W/2), rolling at omega R with a constant
creep ratio 1 - v/(omega R) = xi; the half-period that moves in the drive direction carries
the larger force N1 = N_max, the other N2 = delta^(3/2) N1.  Choices (see ``Eq32Design``):

* omega R and w: the half period is fixed by the scene's nominal period; w = W/a1 is the
  largest value <= ``w_pref`` (2.5) that the stroke allows, and at least 2 (Eq. 32's domain).
* creep xi and delta (``Eq32Design.choose``): delta = 0.5 and xi from Eq. 32 inverted for eps;
  if that xi exceeds its cap, xi = cap and delta from Eq. 32 inverted exactly (a cubic in
  sqrt(delta)).  The cap: with finite friction the creep per step xi w a1 must stay below the
  slip limit mu (E*/G*) a1^2 / R (physics.md), so xi <= ``slip_margin`` (0.5) of that limit
  (and <= creep_max): the design is wearless by construction; with infinite friction creep_max.

``Eq32OpenLoop`` plans at the first tick: velocity |target| / (``horizon_fraction`` x episode
time), driven for the planned time plus the runner's start-up lag (``relaxation_time``, from
the slope of the period impulse), then stops (``Eq32Design.stop``: release, then hold).
``Eq32Feedback`` re-chooses the working point every period from the remaining error and the
runner's measured velocity: a braking curve gives the wanted velocity, the first-order runner
model (relaxation time t_r) the working point that approaches it, an integral (bias) term
what Eq. 32 leaves out (loads, resonance); it stops inside half the tolerance.  (A loop on the
error alone has to be slower than t_r, 0.7-1.5 ms for the 20 g runner, or it overshoots.)

Both have SB3's ``predict(obs, state=None, episode_start=None, deterministic=True)`` and work on
one observation (13,) or a batch (n, 13) (a single env or a VecEnv: ``from_env`` takes
either); they read the error from obs[0] * target_max and keep their own tick counter per env
(reset on ``episode_start``, or on an observation with time_fraction 0, which only a
reset gives).  The action is built by ``rolling_env.env.actions.from_controls``,
the inverse of the env's action mapping ``to_controls`` (one module for both; the compiled
env tick is tested to map actions exactly as ``to_controls``, tests/env/test_env.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from rolling_env.env.actions import from_controls
from rolling_env.env.drive_env import OBS_NAMES
from rolling_env.env.scenes import Scene
from rolling_env.physics import analytic
from rolling_env.validation import check_range

__all__ = ["Eq32Design", "Eq32Feedback", "Eq32OpenLoop", "scene_of"]


@dataclass(frozen=True)
class Eq32Design:
    """The square-wave family of a scene and the Eq. 32 velocities it can reach."""

    scene: Scene
    w_pref: float = 2.5
    slip_margin: float = 0.5
    delta_pref: float = 0.5

    @cached_property  # the design is frozen: computed once
    def a1(self) -> float:
        sc = self.scene
        d1 = analytic.hertz_indentation(sc.N_max, sc.R, sc.E_star)
        return math.sqrt(sc.R * d1)

    @property
    def half_ticks(self) -> int:
        return max(1, self.scene.ticks_per_period // 2)

    def __post_init__(self):
        sc = self.scene
        check_range("w_pref", self.w_pref, 2.0, 1e6)  # Eq. 32 holds for w >= 2 only
        check_range("slip_margin", self.slip_margin, 0.0, 1.0, lo_open=True)
        # delta = 1 gives equal forces: Eq. 32 is zero for every creep and cannot be inverted
        check_range("delta_pref", self.delta_pref, 0.0, 1.0, lo_open=True, hi_open=True)
        w_rate, w_stroke = self._w_limits()
        if min(w_rate, w_stroke) < 2.0:
            need_rate = 2.0 * self.a1 / (self.half_ticks * sc.dt)
            need_stroke = 2.0 * self.a1 / 2 / 0.98
            raise ValueError(
                f"scene {sc.name!r}: Eq. 32 needs a rolling amplitude w = W/a1 >= 2 per half "
                f"period, but omega_R_max = {sc.omega_R_max:g} m/s allows w = {w_rate:.3g} "
                f"and the strokes allow w = {w_stroke:.3g}; the Eq. 32 baselines need "
                f"omega_R_max >= {need_rate:.3g} m/s and stroke_roll, stroke_translate >= "
                f"{need_stroke:.3g} m"
            )

    def _w_limits(self) -> tuple[float, float]:
        """Largest w the rolling rate allows in a half period, and the largest the strokes
        allow (2 % margin)."""
        sc = self.scene
        w_rate = sc.omega_R_max * self.half_ticks * sc.dt / self.a1
        w_stroke = 2 * min(sc.stroke_roll, sc.stroke_translate) / self.a1 * 0.98
        return w_rate, w_stroke

    @cached_property
    def w(self) -> float:
        """w_pref, lowered to what the rate and the strokes allow (never below 2: checked at
        construction)."""
        return min(self.w_pref, *self._w_limits())

    @cached_property
    def omega_R(self) -> float:
        return self.w * self.a1 / (self.half_ticks * self.scene.dt)

    @cached_property
    def creep_cap(self) -> float:
        """Largest creep ratio xi: the wearless window with finite friction, else creep_max."""
        sc = self.scene
        if math.isinf(sc.mu):
            return sc.creep_max
        limit = sc.mu * (sc.E_star / sc.G_star) * self.a1**2 / sc.R  # slip limit at the centre
        return min(sc.creep_max, self.slip_margin * limit / (self.w * self.a1))

    @cached_property
    def delta_min(self) -> float:
        return (self.scene.N_min / self.scene.N_max) ** (2 / 3)

    @cached_property
    def v_max(self) -> float:
        """Fastest Eq. 32 velocity [m/s] of the family (largest creep, smallest delta)."""
        return float(analytic.eq32(self.delta_min, 1 - self.creep_cap, self.w)) * self.omega_R

    def choose(self, speed: float) -> tuple[float, float]:
        """(delta, creep) whose Eq. 32 velocity is ``speed`` [m/s] (saturated to the family).

        Prefer delta = ``delta_pref`` and set the creep by inverting Eq. 32 for eps (small
        creep keeps the stored deflection, the force swings and the runner's ripple small);
        when that creep exceeds the cap, hold the cap and invert Eq. 32 for delta (a cubic in
        sqrt(delta))."""
        speed = min(max(speed, 0.0), self.v_max)
        ratio = speed / self.omega_R
        delta = max(self.delta_pref, self.delta_min)
        creep = 1 - float(analytic.invert_eq32_eps(ratio, delta, self.w))
        if creep <= self.creep_cap:
            return delta, creep
        creep = self.creep_cap
        delta = float(
            np.clip(analytic.invert_eq32_delta(ratio, 1 - creep, self.w), self.delta_min, 1.0)
        )
        return delta, creep

    def speed(self, delta: float, creep: float) -> float:
        return float(analytic.eq32(delta, 1 - creep, self.w)) * self.omega_R

    def action(self, k: int, delta: float, creep: float, direction: int) -> np.ndarray:
        """Action of tick k (0 = episode start) for (delta, creep) and drive direction +-1."""
        sc = self.scene
        h = self.half_ticks
        moving = 1 if ((k + h // 2) // h) % 2 == 0 else -1  # patch moves +c first, from 0
        forth = moving == direction
        N = sc.N_max if forth else sc.N_max * delta**1.5
        return from_controls(sc, N, moving * self.omega_R, creep)

    def relaxation_time(self, delta: float) -> float:
        """Time [s] in which a runner at rest relaxes to the working velocity.

        The period impulse is affine in v* (``analytic.impulse_coefficients``): the mean force
        is -c (v* - v_wp) with c = G* a1^3 Q / ((omega R)^2 tau), so t_r = m / c.  A runner
        started at rest lags the steady motion by v_wp t_r."""
        sc = self.scene
        _, Q = analytic.impulse_coefficients(delta, self.w)
        tau = 2 * self.half_ticks * sc.dt
        return sc.runner_mass * self.omega_R**2 * tau / (sc.G_star * self.a1**3 * Q)

    def stop(self, ticks_stopped: int) -> np.ndarray:
        """Stop driving: one tick at the smallest force releases the stored tangential
        deflection (else the runner springs back by it), then the largest force with no
        rolling and no creep catches the runner on a fresh stuck contact."""
        N = self.scene.N_min if ticks_stopped == 0 else self.scene.N_max
        return from_controls(self.scene, N, 0.0, 0.0)


def scene_of(env) -> Scene:
    """The ``Scene`` of an env, a vector env (SB3 or Gymnasium) or a scene itself."""
    if isinstance(env, Scene):
        return env
    getters = (
        lambda: env.get_attr("scene")[0],  # SB3 VecEnv (wrappers forward)
        lambda: env.unwrapped.scene,  # gymnasium env behind wrappers
        lambda: env.unwrapped.core.scene,
    )  # rolling_env's gymnasium vector env
    for get in getters:
        try:
            sc = get()
        except (AttributeError, IndexError, TypeError):
            continue
        if isinstance(sc, Scene):
            return sc
    raise TypeError(
        f"cannot find the scene of {env!r}: pass a RollingDrive env, vector env or Scene"
    )


TIME_FRACTION = OBS_NAMES.index("time_fraction")


class _Eq32Base:
    def __init__(self, scene: Scene, **design_kw):
        self.design = Eq32Design(scene, **design_kw)
        self.scene = scene
        self._k = None

    @classmethod
    def from_env(cls, env, **kw):
        """Build from the scene of a single env (``gym.make``/``rolling_env.make``), an SB3
        VecEnv (``RollingDriveVecEnv``, possibly wrapped) or a Gymnasium vector env."""
        return cls(scene_of(env), **kw)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(obs, dtype=np.float64)
        single = obs.ndim == 1
        ob = obs.reshape(1, -1) if single else obs
        n = ob.shape[0]
        if self._k is None or len(self._k) != n:
            self._k = np.zeros(n, dtype=np.int64)
            self._reset_all(n)
        starts = (
            np.ones(n, bool)
            if episode_start is None and self._fresh
            else np.asarray(
                episode_start if episode_start is not None else np.zeros(n), bool
            ).reshape(n)
        )
        # a reset observation also says so itself (time_fraction is 0 only there), so a plain
        # Gymnasium loop without episode_start restarts the plan too
        starts = starts | (ob[:, TIME_FRACTION] == 0.0)
        self._fresh = False
        acts = np.empty((n, 3), np.float32)
        for i in range(n):
            if starts[i]:
                self._k[i] = 0
                self._start(i, ob[i])
            acts[i] = self._act(i, ob[i])
            self._k[i] += 1
        return (acts[0] if single else acts), state

    _fresh = True

    def _error(self, o) -> float:
        return float(o[0]) * self.scene.target_max


class Eq32OpenLoop(_Eq32Base):
    """Plan once from the target and the horizon, hold the excitation, stop when done."""

    def __init__(self, scene: Scene, horizon_fraction: float = 0.8, **design_kw):
        super().__init__(scene, **design_kw)
        if not 0 < horizon_fraction <= 1:
            raise ValueError(f"horizon_fraction must be in (0, 1], got {horizon_fraction}")
        self.horizon_fraction = horizon_fraction

    def _reset_all(self, n):
        self._plan = [(1, 1.0, 0.0, 0)] * n

    def _start(self, i, o):
        target = self._error(o)  # x* = 0 at the start
        T = self.horizon_fraction * self.scene.episode_steps * self.scene.dt
        delta, creep = self.design.choose(abs(target) / T)
        v = self.design.speed(delta, creep)
        # drive for the planned time plus the start-up lag of the runner (v_wp t_r)
        t_drive = abs(target) / v + self.design.relaxation_time(delta) if v > 0 else 0.0
        ticks = int(round(t_drive / self.scene.dt))
        self._plan[i] = (1 if target >= 0 else -1, delta, creep, ticks)

    def _act(self, i, o):
        direction, delta, creep, ticks = self._plan[i]
        if self._k[i] >= ticks:
            return self.design.stop(int(self._k[i]) - ticks)
        return self.design.action(int(self._k[i]), delta, creep, direction)


class Eq32Feedback(_Eq32Base):
    """Re-choose the working point each period from the remaining error and the runner's speed.

    A heavy runner does not jump to the working velocity: the period-mean force of the contact
    is c (v_wp - v*) with c = m / t_r (``Eq32Design.relaxation_time``), so the runner relaxes
    to v_wp with the time constant t_r (0.7-1.5 ms for the 20 g runner, about half the
    episode).  A loop on the error alone must be slower than t_r or it overshoots.  This
    controller closes two loops, once per period (tau), on the first-order runner model:

    * position: the wanted velocity ``v_des = sign(e) min(sqrt(2 a_b |e|), |e| / T_f)`` (the
      braking curve of the deceleration ``a_b`` = ``brake_fraction`` of the largest the
      family gives, v_max / t_r; near the target a first-order approach in
      ``T_f = approach_periods`` periods);
    * velocity: the mean velocity of the next period should be
      ``v_next = v_des + (v - v_des) exp(-tau / T_v)`` (``T_v = velocity_periods`` periods),
      v the measured mean velocity of the last period (from the change of the error).  The
      model's mean velocity over a period at a fixed working point is
      ``v_wp + b + (v - v_wp - b) r``, r = (1 - exp(-tau/t_r)) t_r / tau, solved for v_wp and
      saturated to +-v_max (a negative v_wp is the mirrored pattern).  ``b`` is an additive
      velocity bias learned from the model's misprediction each period (gain
      ``bias_gain``): what Eq. 32 leaves out (a load on the runner, inertia effects near
      resonance) acts on the loop as such a bias, and this integral action removes it.

    (delta, creep) come from Eq. 32 inverted exactly (``Eq32Design.choose``), inside the
    wearless window.  The drive stops (release, then hold; ``Eq32Design.stop``) when
    |e| < ``stop_fraction`` x tolerance and the runner is slow (|v| T_f below the same), and
    resumes once |e| exceeds the tolerance.
    """

    def __init__(
        self,
        scene: Scene,
        approach_periods: float = 3.0,
        velocity_periods: float = 2.0,
        brake_fraction: float = 0.5,
        bias_gain: float = 0.3,
        stop_fraction: float = 0.5,
        **design_kw,
    ):
        super().__init__(scene, **design_kw)
        for name, val in (
            ("approach_periods", approach_periods),
            ("velocity_periods", velocity_periods),
        ):
            if not val > 0:
                raise ValueError(f"{name} must be > 0, got {val}")
        for name, val in (("brake_fraction", brake_fraction), ("stop_fraction", stop_fraction)):
            if not 0 < val <= 1:
                raise ValueError(f"{name} must be in (0, 1], got {val}")
        if not 0 <= bias_gain <= 1:
            raise ValueError(f"bias_gain must be in [0, 1], got {bias_gain}")
        d = self.design
        self.tau = 2 * d.half_ticks * scene.dt
        self.T_f = approach_periods * self.tau
        self.T_v = velocity_periods * self.tau
        self.bias_gain = bias_gain
        self.stop_fraction = stop_fraction
        t_r0 = d.relaxation_time(d.delta_min)
        self.a_brake = brake_fraction * d.v_max / t_r0 if t_r0 > 0 else math.inf

    def _reset_all(self, n):
        self._cmd = [(1, 1.0, 0.0, False)] * n
        self._idle = np.zeros(n, dtype=np.int64)
        self._e_prev = np.zeros(n)
        self._k_prev = np.zeros(n, dtype=np.int64)
        self._bias = np.zeros(n)
        self._pred = np.full(n, np.nan)  # predicted mean velocity of the running period
        self._r = np.zeros(n)

    def _start(self, i, o):
        self._cmd[i] = (1, 1.0, 0.0, False)
        self._idle[i] = 0
        self._e_prev[i] = self._error(o)
        self._k_prev[i] = 0
        self._bias[i] = 0.0
        self._pred[i] = np.nan

    def _ratio(self, delta: float) -> float:
        """r = mean over one period of (v - v_wp) / (v_start - v_wp) for the first-order model."""
        t_r = self.design.relaxation_time(delta)
        if t_r <= 0:
            return 0.0
        x = self.tau / t_r
        return -math.expm1(-x) / x

    def plan(self, e: float, v: float, bias: float = 0.0) -> tuple[float, float, float]:
        """(signed working velocity v_wp [m/s], r, predicted mean velocity of the period) for
        error ``e`` [m], runner velocity ``v`` [m/s] and learned bias [m/s]."""
        d = self.design
        v_des = math.copysign(min(math.sqrt(2 * self.a_brake * abs(e)), abs(e) / self.T_f), e)
        v_next = v_des + (v - v_des) * math.exp(-self.tau / self.T_v)
        delta, v_wp, r = d.delta_pref, v_next, 0.0
        for _ in range(3):  # t_r depends on the delta that the working point needs
            r = self._ratio(delta)
            v_wp = float(np.clip((v_next - v * r) / (1 - r) - bias, -d.v_max, d.v_max))
            delta, _ = d.choose(abs(v_wp))
        r = self._ratio(delta)
        return v_wp, r, v_wp + bias + (v - v_wp - bias) * r

    def _act(self, i, o):
        k = int(self._k[i])
        h = self.design.half_ticks
        tol = self.scene.tolerance
        if k == 0 or (k + h // 2) % (2 * h) == 0:  # re-plan once per period
            e = self._error(o)
            v = (self._e_prev[i] - e) / ((k - self._k_prev[i]) * self.scene.dt) if k > 0 else 0.0
            if np.isfinite(self._pred[i]) and self._r[i] < 1:
                # misprediction of the period's mean velocity -> bias of the working point
                self._bias[i] += self.bias_gain * (v - self._pred[i])
            self._e_prev[i], self._k_prev[i] = e, k
            was_idle = self._cmd[i][3]
            lim = self.stop_fraction * tol
            if (was_idle and abs(e) <= tol) or (abs(e) < lim and abs(v) * self.T_f < lim):
                self._cmd[i] = (1, 1.0, 0.0, True)
                self._pred[i] = np.nan
            else:
                v_wp, self._r[i], self._pred[i] = self.plan(e, v, self._bias[i])
                delta, creep = self.design.choose(abs(v_wp))
                self._cmd[i] = (1 if v_wp >= 0 else -1, delta, creep, False)
        direction, delta, creep, idle = self._cmd[i]
        if idle:
            self._idle[i] += 1
            return self.design.stop(int(self._idle[i]) - 1)
        self._idle[i] = 0
        return self.design.action(k, delta, creep, direction)
