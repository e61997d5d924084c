"""RollingDrive-v0: learn the excitation of the oscillating-rolling nanodrive."""
from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from .actions import to_controls
from .model import Drive, DriveParams
from .scenes import Scene, load_scene

OBS_NAMES = (
    "error", "vstar", "roll_pos", "translate_pos", "normal_force", "tangential_force",
    "stick_fraction", "clock_sin", "clock_cos", "time_fraction", "last_N", "last_roll",
    "last_creep",
)
OBS_BOUND = 10.0


class RollingDriveEnv(gym.Env):
    r"""
    ## Description
    A rigid sphere (radius ``R``) is pressed with a normal force ``N`` on an elastic runner of
    mass ``m`` and rolled (rate ``omega``) and translated (rate ``v``) back and forth.  With a
    larger force in the *forth* step than in the *back* step, the tangential creep acts on
    different contact areas and the runner creeps (Wetter & Popov 2015).  The contact is the
    MDR spring row of ``rolling_env.model`` with finite Coulomb friction (slip = wear) and
    finite runner inertia, advanced ``sub_steps`` times per control tick.  The task: move the
    runner to a target displacement, with little slip work (wear).

    Everything physical is fixed by a *scene* (``configs/scenes/*.yaml``): see
    ``rolling_env.scenes.Scene`` for the keys and their SI units.

    ## Action Space
    ``Box(-1, 1, (3,), float32)``, held for one control tick (``scene.dt`` seconds):

    | Num | Action    | Physical value                                                       |
    |-----|-----------|----------------------------------------------------------------------|
    | 0   | force     | ``N = N_min + (a0 + 1)/2 (N_max - N_min)`` [N]                       |
    | 1   | rolling   | ``omega R = a1 * omega_R_max`` [m/s], signed (+: forth)              |
    | 2   | creep     | ``v = omega R (1 - a2 * creep_max)`` [m/s]: a2 sets the creep ratio  |
    |     |           | ``1 - v/(omega R) = a2 * creep_max``, so the narrow useful window of |
    |     |           | a finite-friction drive (``|1 - eps|`` ~ 1e-3) spans the whole axis  |

    The rolling travel ``c = integral omega R dt`` and the translation travel
    ``integral v dt`` are limited to ``+-stroke_roll`` and ``+-stroke_translate``: a tick that
    would pass a limit is slowed (both rates by the same factor, so the creep ratio is kept) to
    end exactly at it; ``info["saturation"]`` is that factor (1 = not saturated).  Actions
    must be finite, of shape (3,) and inside [-1, 1] (a tolerance of 1e-6 is clipped): anything
    else raises ``ValueError``.

    ## Observation Space
    ``Box(-10, 10, (13,), float32)``; values are clipped to the bounds:

    | Num | Observation       | Definition                                                 |
    |-----|-------------------|------------------------------------------------------------|
    | 0   | error             | (target - x*) / target_max                                 |
    | 1   | vstar             | v* / (0.3 creep_max omega_R_max)                            |
    | 2   | roll_pos          | c / stroke_roll  (rolling travel, in [-1, 1])               |
    | 3   | translate_pos     | integral v dt / stroke_translate  (in [-1, 1])              |
    | 4   | normal_force      | N / N_max                                                  |
    | 5   | tangential_force  | T / T_ref, T_ref = min(mu N_max, 2 a_max G* creep_max stroke_roll) |
    | 6   | stick_fraction    | stuck share of the contact length (1 with mu = inf)        |
    | 7   | clock_sin         | sin(2 pi t / period)  (nominal excitation clock)           |
    | 8   | clock_cos         | cos(2 pi t / period)                                       |
    | 9   | time_fraction     | step / episode_steps                                       |
    | 10-12 | last action     | the previous action (force, rolling, creep)                |

    ## Rewards
    Per tick ``reward = reward_track + reward_wear`` with
    ``reward_track = -w_track |target - x*| / target_max`` and
    ``reward_wear = -w_wear * slip_work / wear_ref``, where ``slip_work`` is the friction
    work of the tick [J] (Archard: wear volume ~ friction work) and
    ``wear_ref = mu N_max creep_max omega_R_max dt`` (the slip work of a tick of full sliding at
    the largest rates; 1 J with mu = inf, where the term is always 0).  ``info`` holds both
    terms; they add up exactly to the reward.

    ## Starting State
    Runner at rest at x* = 0, sphere centred (both travels 0), springs released, no contact
    until the first action.  The target is drawn uniformly from ``[target_min, target_max]``
    (with a random sign if ``target_both_signs``) with the env's seeded generator, or given by
    ``reset(options={"target": x})`` in metres.

    ## Episode End
    No terminal state (``terminated`` is always False).  Episodes are truncated by the
    ``TimeLimit`` that registration adds (``max_episode_steps``, 512 = the shipped scenes'
    ``episode_steps``); the env itself never truncates.  ``rolling_env.make(scene)`` uses the
    scene's ``episode_steps``.

    ## Arguments
    ``gym.make("RollingDrive-v0", scene="default", render_mode=None, **overrides)``: ``scene``
    is a shipped scene name (``rolling_env.list_scenes()``), a path to a YAML file, a dict or a
    ``Scene``; ``overrides`` replace scene keys (``mu=0.1``, ``runner_mass=0.01``, ...) with the
    same validation.  ``render_mode`` is ``"rgb_array"`` (a uint8 frame of the contact and the
    runner against its target) or ``"human"`` (the same frame in a matplotlib window).

    ## Version History
    * v0: initial version.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 30}

    def __init__(self, scene: str | dict | Scene = "default", render_mode: str | None = None,
                 **overrides):
        self.scene = load_scene(scene, **overrides)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']} or None,"
                             f" got {render_mode!r}")
        self.render_mode = render_mode
        sc = self.scene
        self.params = DriveParams(sc.R, sc.E_star, sc.G_star, mu=sc.mu,
                                  m=sc.runner_mass, F_ext=sc.F_ext)
        d_max = (3 * sc.N_max / (4 * sc.E_star * math.sqrt(sc.R))) ** (2 / 3)
        self.a_max = math.sqrt(sc.R * d_max)
        self.drive = Drive(self.params, a_ref=self.a_max, resolution=sc.resolution,
                           stroke=(-sc.stroke_roll, sc.stroke_roll), a_max=self.a_max,
                           t_ref=sc.period)
        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = spaces.Box(-OBS_BOUND, OBS_BOUND, (len(OBS_NAMES),), np.float32)
        self.v_ref = 0.3 * sc.creep_max * sc.omega_R_max
        T_stuck = 2 * self.a_max * sc.G_star * sc.creep_max * sc.stroke_roll
        self.T_ref = min(sc.mu * sc.N_max, T_stuck)
        self.wear_ref = (sc.mu * sc.N_max * sc.creep_max * sc.omega_R_max * sc.dt
                         if math.isfinite(sc.mu) else 1.0)
        self.dt = sc.dt
        self.target = 0.0
        self._step = 0
        self._last = np.zeros(3)
        self._out = None
        self._history = []

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        sc = self.scene
        if options is not None and "target" in options:
            t = options["target"]
            try:
                t = float(t)
            except (TypeError, ValueError):
                raise ValueError(f"options['target'] must be a number [m], got {t!r}") from None
            if not math.isfinite(t) or abs(t) > 1.0:
                raise ValueError(f"options['target'] must be a finite displacement in [-1, 1] m, "
                                 f"got {t!r}")
            self.target = t
        else:
            mag = self.np_random.uniform(sc.target_min, sc.target_max)
            sign = self.np_random.choice((-1.0, 1.0)) if sc.target_both_signs else 1.0
            self.target = float(sign * mag)
        self.drive.reset()
        self._step = 0
        self._last = np.zeros(3)
        self._out = {"N": 0.0, "T": 0.0, "stick_fraction": 0.0}
        self._history = [0.0]
        return self._obs(), self._info(0.0, 0.0, 1.0, 0.0, 0.0)

    def step(self, action):
        a = self._check_action(action)
        sc = self.scene
        N, u, v = to_controls(sc, a)
        f = min(_travel_factor(self.drive.c, u * self.dt, sc.stroke_roll),
                _travel_factor(self.drive.x_sphere, v * self.dt, sc.stroke_translate))
        u *= f
        v *= f
        out = self.drive.run(dt_tick=self.dt, n_sub=sc.sub_steps, omega_R=u, v=v, N=N)
        self._out = {k: float(val[0]) for k, val in out.items()}
        self._step += 1
        self._last = a
        self._history.append(self.drive.xstar)
        err = self.target - self.drive.xstar
        r_track = -sc.w_track * abs(err) / sc.target_max
        slip = self._out["slip_work"]
        r_wear = -sc.w_wear * slip / self.wear_ref
        reward = r_track + r_wear
        obs = self._obs()
        if not (np.all(np.isfinite(obs)) and math.isfinite(reward)):
            raise FloatingPointError("non-finite state after a physics tick")
        info = self._info(r_track, r_wear, f, u, v)
        if self.render_mode == "human":
            self.render()
        return obs, float(reward), False, False, info

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; set render_mode='rgb_array'")
            return None
        from .render import render_frame
        frame = render_frame(self)
        if self.render_mode == "human":
            from .render import show
            show(frame)
            return None
        return frame

    def close(self):
        from .render import close
        close()

    # ------------------------------------------------------------------ helpers
    def _check_action(self, action) -> np.ndarray:
        a = np.asarray(action, dtype=np.float64)
        if a.shape != (3,):
            raise ValueError(f"action must have shape (3,), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"action must be finite, got {a.tolist()}")
        if np.any(np.abs(a) > 1.0 + 1e-6):
            raise ValueError(f"action must lie in [-1, 1] (the action space), got {a.tolist()}")
        return np.clip(a, -1.0, 1.0)

    def _obs(self) -> np.ndarray:
        sc, drv, o = self.scene, self.drive, self._out
        t = self._step * self.dt
        ph = 2 * math.pi * t / sc.period
        obs = np.array([
            (self.target - drv.xstar) / sc.target_max,
            drv.vstar / self.v_ref,
            drv.c / sc.stroke_roll,
            drv.x_sphere / sc.stroke_translate,
            o["N"] / sc.N_max,
            o["T"] / self.T_ref,
            o["stick_fraction"],
            math.sin(ph), math.cos(ph),
            self._step / sc.episode_steps,
            self._last[0], self._last[1], self._last[2],
        ])
        return np.clip(obs, -OBS_BOUND, OBS_BOUND).astype(np.float32)

    def _info(self, r_track, r_wear, f, u, v) -> dict:
        o, drv = self._out, self.drive
        return {
            "reward_track": r_track,
            "reward_wear": r_wear,
            "target": self.target,
            "xstar": drv.xstar,
            "vstar": drv.vstar,
            "error": self.target - drv.xstar,
            "slip_work": o.get("slip_work", 0.0),
            "N": o["N"],
            "T": o["T"],
            "stick_fraction": o["stick_fraction"],
            "omega_R": u,
            "v": v,
            "saturation": f,
            "saturated": f < 1.0,
        }


def _travel_factor(pos: float, step: float, limit: float) -> float:
    """Largest f in [0, 1] with |pos + f step| <= limit."""
    new = pos + step
    if abs(new) <= limit or step == 0.0:
        return 1.0
    room = (math.copysign(limit, step) - pos) / step
    return float(min(max(room, 0.0), 1.0)) if room > 1e-12 else 0.0
