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
``Eq32Feedback`` re-chooses the velocity every period from the remaining error,
v = clip(error / ``time_constant``, +-v_max) (time constant at least twice the runner's
relaxation time, so the loop does not ring), and stops driving inside half the tolerance.

Both have SB3's ``predict(obs, state=None, episode_start=None, deterministic=True)`` and work on
one observation (13,) or a batch (n, 13); they read the error from obs[0] * target_max and keep
their own tick counter per env (reset on ``episode_start``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rolling_env import analytic
from rolling_env.actions import from_controls
from rolling_env.scenes import Scene


@dataclass(frozen=True)
class Eq32Design:
    """The square-wave family of a scene and the Eq. 32 velocities it can reach."""

    scene: Scene
    w_pref: float = 2.5
    slip_margin: float = 0.5
    delta_pref: float = 0.5

    @property
    def a1(self) -> float:
        sc = self.scene
        d1 = analytic.hertz_indentation(sc.N_max, sc.R, sc.E_star)
        return math.sqrt(sc.R * d1)

    @property
    def half_ticks(self) -> int:
        return max(1, self.scene.ticks_per_period // 2)

    @property
    def w(self) -> float:
        sc = self.scene
        t_half = self.half_ticks * sc.dt
        w_rate = sc.omega_R_max * t_half / self.a1           # fastest rolling
        w_stroke = 2 * min(sc.stroke_roll, sc.stroke_translate) / self.a1 * 0.98
        return max(2.0, min(self.w_pref, w_rate, w_stroke))

    @property
    def omega_R(self) -> float:
        return self.w * self.a1 / (self.half_ticks * self.scene.dt)

    @property
    def creep_cap(self) -> float:
        """Largest creep ratio xi: the wearless window with finite friction, else creep_max."""
        sc = self.scene
        if math.isinf(sc.mu):
            return sc.creep_max
        limit = sc.mu * (sc.E_star / sc.G_star) * self.a1 ** 2 / sc.R  # slip limit at the centre
        return min(sc.creep_max, self.slip_margin * limit / (self.w * self.a1))

    @property
    def delta_min(self) -> float:
        return (self.scene.N_min / self.scene.N_max) ** (2 / 3)

    @property
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
        delta = float(np.clip(analytic.invert_eq32_delta(ratio, 1 - creep, self.w),
                              self.delta_min, 1.0))
        return delta, creep

    def speed(self, delta: float, creep: float) -> float:
        return float(analytic.eq32(delta, 1 - creep, self.w)) * self.omega_R

    def action(self, k: int, delta: float, creep: float, direction: int) -> np.ndarray:
        """Action of tick k (0 = episode start) for (delta, creep) and drive direction +-1."""
        sc = self.scene
        h = self.half_ticks
        moving = 1 if ((k + h // 2) // h) % 2 == 0 else -1   # patch moves +c first, from 0
        forth = moving == direction
        N = sc.N_max if forth else sc.N_max * delta ** 1.5
        return from_controls(sc, N, moving * self.omega_R, creep)

    def relaxation_time(self, delta: float) -> float:
        """Time [s] in which a runner at rest relaxes to the working velocity.

        The period impulse is affine in v* (``analytic.impulse_coefficients``): the mean force
        is -c (v* - v_wp) with c = G* a1^3 Q / ((omega R)^2 tau), so t_r = m / c.  A runner
        started at rest lags the steady motion by v_wp t_r."""
        sc = self.scene
        _, Q = analytic.impulse_coefficients(delta, self.w)
        tau = 2 * self.half_ticks * sc.dt
        return sc.runner_mass * self.omega_R ** 2 * tau / (sc.G_star * self.a1 ** 3 * Q)

    def stop(self, ticks_stopped: int) -> np.ndarray:
        """Stop driving: one tick at the smallest force releases the stored tangential
        deflection (else the runner springs back by it), then the largest force with no
        rolling and no creep catches the runner on a fresh stuck contact."""
        N = self.scene.N_min if ticks_stopped == 0 else self.scene.N_max
        return from_controls(self.scene, N, 0.0, 0.0)


class _Eq32Base:
    def __init__(self, scene: Scene, **design_kw):
        self.design = Eq32Design(scene, **design_kw)
        self.scene = scene
        self._k = None

    @classmethod
    def from_env(cls, env, **kw):
        return cls(env.unwrapped.scene if hasattr(env, "unwrapped") else env.get_attr("scene")[0],
                   **kw)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(obs, dtype=np.float64)
        single = obs.ndim == 1
        ob = obs.reshape(1, -1) if single else obs
        n = ob.shape[0]
        if self._k is None or len(self._k) != n:
            self._k = np.zeros(n, dtype=np.int64)
            self._reset_all(n)
        starts = (np.ones(n, bool) if episode_start is None and self._fresh
                  else np.asarray(episode_start if episode_start is not None else np.zeros(n),
                                  bool).reshape(n))
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
    """Re-choose the working-point velocity each period from the remaining error."""

    def __init__(self, scene: Scene, time_constant_periods: float = 4.0, **design_kw):
        super().__init__(scene, **design_kw)
        # slower than twice the runner's relaxation, or the loop rings
        self.time_constant = max(time_constant_periods * scene.period,
                                 2.0 * self.design.relaxation_time(0.5))

    def _reset_all(self, n):
        self._cmd = [(1, 1.0, 0.0, False)] * n
        self._idle = np.zeros(n, dtype=np.int64)

    def _start(self, i, o):
        self._cmd[i] = (1, 1.0, 0.0, False)
        self._idle[i] = 0

    def _act(self, i, o):
        k = int(self._k[i])
        h = self.design.half_ticks
        if k == 0 or (k + h // 2) % (2 * h) == 0:  # re-plan once per period
            e = self._error(o)
            if abs(e) < 0.5 * self.scene.tolerance:
                self._cmd[i] = (1, 1.0, 0.0, True)
            else:
                delta, creep = self.design.choose(abs(e) / self.time_constant)
                self._cmd[i] = (1 if e > 0 else -1, delta, creep, False)
        direction, delta, creep, idle = self._cmd[i]
        if idle:
            self._idle[i] += 1
            return self.design.stop(int(self._idle[i]) - 1)
        self._idle[i] = 0
        return self.design.action(k, delta, creep, direction)
