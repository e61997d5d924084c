"""Period-level agents: one decision per excitation period, in the design space of Eq. 32.

The policy's action (4 numbers in [-1, 1]) is the next period's working point of the paper's
square wave (``PeriodExcitation``), executed tick by tick:

* ``drive`` (a[0]): the drive direction (its sign) and strength: the force ratio
  delta = 1 - |a[0]| (1 - delta_min), +-1 as fast as the scene's N_min allows.  Where
  |a[0]| < ``HOLD`` (nearly equal forces, which would drive nowhere) the period holds: one tick at
  N_min releases the stored tangential deflection (on entering a hold only), then N_max with
  no rolling and no creep keeps the runner on a stuck contact (the baselines' stop);
* ``creep`` (a[1]): the creep ratio xi in [0, creep_cap] (``Eq32Design.creep_cap``: half the
  slip limit at the design's w; at the largest w the creep per step reaches 0.8 of it, still
  within it);
* ``stroke`` (a[2]): the rolling amplitude w = W/a1 in [2, w_max] (Eq. 32's domain, within
  what the rate and the strokes allow);
* ``force`` (a[3]): the larger force N1 in [N_min, N_max]; the smaller is delta^1.5 N1.

A policy therefore makes 64 decisions in a 512-tick episode instead of 512, and its actions
read as an excitation law: an action with delta, xi and w of an Eq. 32 design (``encode``)
executes that design's ticks exactly (tested against ``Eq32Design.action``).

Training wraps the vector env in ``PeriodVecEnv`` (``agents.train`` does so for the
hyper-parameter key ``period_actions: true`` or ``--period-actions``): each of its steps runs
one period of the wrapped env, sums the rewards and the additive infos (slip work, reward
terms) and returns the last tick's observation.  Evaluation and ``rolling-drive rollout``
wrap the loaded policy in ``PeriodAgent``, which acts tick by tick.
"""

from __future__ import annotations

import numpy as np
from stable_baselines3.common.vec_env import VecEnvWrapper

from rolling_env.env.actions import from_controls
from rolling_env.env.baselines import TIME_FRACTION, Eq32Design, scene_of

N_ACTION = 4
HOLD = 0.05  # |drive| below this holds the runner for the period
#: infos summed over a period's ticks (the rest are the last tick's)
ADDITIVE_INFOS = ("slip_work", "reward_track", "reward_wear", "reward_final")


class PeriodExcitation:
    """The square wave of one period from a period action, tick by tick."""

    def __init__(self, scene):
        self.scene = sc = scene_of(scene)
        self.design = Eq32Design(sc)  # refuses a scene where Eq. 32's w >= 2 is out of reach
        self.ticks = 2 * self.design.half_ticks
        self.w_max = min(self.design._w_limits())
        if sc.episode_steps % self.ticks:
            raise ValueError(
                f"scene {sc.name!r}: period actions need episodes of whole periods, but "
                f"episode_steps = {sc.episode_steps} is no multiple of the "
                f"{self.ticks} ticks of a period"
            )

    def decode(self, action) -> dict:
        """The working point of a period action (clipped to [-1, 1])."""
        a = np.clip(np.asarray(action, dtype=np.float64).reshape(N_ACTION), -1.0, 1.0)
        sc, d = self.scene, self.design
        unit = (a + 1.0) / 2.0
        return {
            "hold": bool(abs(a[0]) < HOLD),
            "direction": 1 if a[0] >= 0 else -1,
            "delta": 1.0 - abs(a[0]) * (1.0 - d.delta_min),
            "creep": unit[1] * d.creep_cap,
            "w": 2.0 + unit[2] * (self.w_max - 2.0),
            "N1": sc.N_min + unit[3] * (sc.N_max - sc.N_min),
        }

    def encode(self, delta: float, creep: float, w: float, direction: int = 1, N1=None):
        """The period action of a working point (the inverse of ``decode`` outside the hold
        band: a delta so near 1 that |drive| < ``HOLD`` decodes as a hold)."""
        sc, d = self.scene, self.design
        N1 = sc.N_max if N1 is None else N1
        drive = (1.0 - delta) / (1.0 - d.delta_min) * (1 if direction >= 0 else -1)
        return np.array(
            [
                drive,
                2.0 * creep / d.creep_cap - 1.0 if d.creep_cap > 0 else -1.0,
                2.0 * (w - 2.0) / (self.w_max - 2.0) - 1.0 if self.w_max > 2.0 else -1.0,
                2.0 * (N1 - sc.N_min) / (sc.N_max - sc.N_min) - 1.0,
            ],
            dtype=np.float64,
        )

    def tick(self, j: int, point: dict, was_holding: bool) -> np.ndarray:
        """Env action of tick ``j`` (0 .. ticks-1) of a period at ``point`` (``decode``);
        ``was_holding``: the period before held (no release tick then)."""
        sc, d = self.scene, self.design
        if point["hold"]:
            N = sc.N_min if (j == 0 and not was_holding) else sc.N_max
            return from_controls(sc, N, 0.0, 0.0)
        h = d.half_ticks
        moving = 1 if ((j + h // 2) // h) % 2 == 0 else -1  # as Eq32Design.action
        forth = moving == point["direction"]
        N1 = point["N1"]
        N = N1 if forth else max(sc.N_min, N1 * point["delta"] ** 1.5)
        omega_R = point["w"] * d.a1 / (h * sc.dt)
        return from_controls(sc, N, moving * omega_R, point["creep"])


def _box():
    from gymnasium import spaces

    return spaces.Box(-1.0, 1.0, (N_ACTION,), np.float32)


class PeriodVecEnv(VecEnvWrapper):
    """SB3 VecEnv wrapper: each step runs one excitation period of the wrapped env from a
    period action per env (``PeriodExcitation``), with the rewards and the additive infos
    summed over the period.  Episodes end on a period's last tick (checked: episodes of whole
    periods); an env that ends earlier is an error."""

    def __init__(self, venv):
        self.excitation = PeriodExcitation(scene_of(venv))
        super().__init__(venv, action_space=_box())
        self._holding = np.zeros(venv.num_envs, bool)
        self._points = None

    def reset(self):
        self._holding[:] = False
        return self.venv.reset()

    def step_async(self, actions):
        self._points = [self.excitation.decode(a) for a in np.asarray(actions)]

    def step_wait(self):
        ex, n = self.excitation, self.num_envs
        total = np.zeros(n)
        sums = [dict.fromkeys(ADDITIVE_INFOS, 0.0) for _ in range(n)]
        for j in range(ex.ticks):
            acts = np.stack([ex.tick(j, p, h) for p, h in zip(self._points, self._holding)])
            self.venv.step_async(acts)
            obs, rew, done, infos = self.venv.step_wait()
            total += rew
            for s, info in zip(sums, infos):
                for k in ADDITIVE_INFOS:
                    s[k] += info.get(k, 0.0)
            if done.any() and j < ex.ticks - 1:
                raise RuntimeError(
                    f"an episode ended on tick {j + 1} of a {ex.ticks}-tick period: period "
                    "actions need episodes of whole periods"
                )
        for s, info in zip(sums, infos):
            info.update(s)
        self._holding = np.array([p["hold"] for p in self._points]) & ~done
        return obs, total.astype(np.float32), done, infos


class PeriodAgent:
    """A loaded period-level policy (SB3's ``predict``, observation statistics applied) acting
    tick by tick: at each period's first tick it decides the period from the observation
    then, and plays the period's ticks.  Episode starts come from ``episode_start`` or from a
    reset observation (time_fraction 0), as for the baselines."""

    def __init__(self, policy, scene):
        self.policy = policy
        self.excitation = PeriodExcitation(scene)
        self._k = None

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        obs = np.asarray(obs, dtype=np.float32)
        single = obs.ndim == 1
        ob = obs.reshape(1, -1) if single else obs
        n, ex = ob.shape[0], self.excitation
        if self._k is None or len(self._k) != n:
            self._k = np.zeros(n, np.int64)
            self._points = [None] * n
            self._holding = np.zeros(n, bool)
            episode_start = np.ones(n, bool)
        starts = np.zeros(n, bool) if episode_start is None else np.asarray(episode_start, bool)
        starts = starts.reshape(n) | (ob[:, TIME_FRACTION] == 0.0)
        self._k[starts] = 0
        self._holding[starts] = False
        new = np.flatnonzero(self._k % ex.ticks == 0)
        if new.size:
            a, _ = self.policy.predict(ob[new], deterministic=deterministic)
            for i, row in zip(new, np.asarray(a).reshape(len(new), N_ACTION)):
                if self._points[i] is not None and self._k[i] > 0:
                    self._holding[i] = self._points[i]["hold"]
                self._points[i] = ex.decode(row)
        acts = np.stack(
            [
                ex.tick(int(self._k[i] % ex.ticks), self._points[i], self._holding[i])
                for i in range(n)
            ]
        )
        self._k += 1
        return (acts[0] if single else acts), state


def check_period_actions(value) -> bool:
    """The hyper-parameter ``period_actions``: true or false."""
    if not isinstance(value, bool):
        raise ValueError(f"period_actions must be true or false, got {value!r}")
    return value


__all__ = [
    "HOLD",
    "N_ACTION",
    "PeriodAgent",
    "PeriodExcitation",
    "PeriodVecEnv",
    "check_period_actions",
]
