"""RollingDrive-v0: learn the excitation of the oscillating-rolling nanodrive."""

from __future__ import annotations

import math
import numbers
from collections.abc import Mapping

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from rolling_env.env import _envkernel as EK
from rolling_env.env.scenes import EPISODE_STEPS_MAX, Scene, draw_physics, episode_scene, load_scene
from rolling_env.physics import _kernel as K
from rolling_env.physics.kernel_state import check_flags
from rolling_env.physics.model import Drive, DriveParams

OBS_NAMES = EK.OBS_NAMES  # the observation, in order (one list: the kernel writes it)
OBS_BOUND = EK.OBS_BOUND


class RollingDriveEnv(gym.Env):
    r"""
    ## Description
    A rigid sphere (radius ``R``) is pressed with a normal force ``N`` on an elastic runner of
    mass ``m`` and rolled (rate ``omega``) and translated (rate ``v``) back and forth.  With a
    larger force in the *forth* step than in the *back* step, the tangential creep acts on
    different contact areas and the runner creeps (Wetter & Popov 2015).  The contact is the
    MDR spring row of ``rolling_env.physics.model`` with finite Coulomb friction (slip = wear) and
    finite runner inertia, advanced ``n_sub`` sub-steps per control tick (the scene's
    ``sub_steps``, or with ``sub_steps: auto`` as many as its ``accuracy`` asks for,
    ``Scene.n_sub``; docs/numerics.md).  The task: move the
    runner to a target displacement, with little slip work (wear).

    Everything physical is fixed by a *scene* (``configs/scenes/*.yaml``): see
    ``rolling_env.env.scenes.Scene`` for the keys and their SI units.

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
    | 6   | stick_fraction    | share of the contact not slipping now (1 with mu = inf)    |
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
    the largest rates; 1 J with mu = inf, where the term is always 0).  With the scene key
    ``w_final`` > 0 (default 0; ``gym.make(..., w_final=20.0)``) the episode's last tick
    (step ``episode_steps``) adds ``reward_final = -w_final |target - x*| / tolerance``: the
    final error as the comparison scores it.  ``info`` holds the three terms; they add up to
    the reward.

    ## Starting State
    Runner at rest at x* = 0, sphere centred (both travels 0), springs released, no contact
    until the first action.  The target is drawn uniformly from ``[target_min, target_max]``
    (with a random sign if ``target_both_signs``) with the env's seeded generator, or given by
    ``reset(options={"target": x})`` in metres, |x| <= 10 target_max (where the error
    observation saturates), of either sign whatever ``target_both_signs`` says (that key
    governs the random draws only: in ``loaded`` a negative target runs with the load);
    "target" is the only option.

    A scene with ``randomize`` (docs/environment.md) draws mu, runner_mass and F_ext per
    episode at reset, after the target; ``info["scene_draw"]`` holds the draw.

    ## Episode End
    No terminal state (``terminated`` is always False).  The env truncates after the scene's
    ``episode_steps`` ticks (512 in the shipped scenes; ``episode_steps=n`` overrides it), the
    same count that ``time_fraction`` uses.  ``gym.make(..., max_episode_steps=n)`` adds a
    ``TimeLimit`` that can end episodes earlier.  One longer than ``episode_steps`` could never
    be reached: ``rolling_env.make``, ``gym.make_vec`` in its default mode (this env's
    ``vector_entry_point``) and the batched envs reject it (set ``episode_steps`` instead).
    ``gym.make`` and ``make_vec``'s "sync"/"async" modes hide their ``TimeLimit`` from the env
    (Gymnasium gives the env a spec without ``max_episode_steps``), so there a longer limit has
    no effect: episodes still end at ``episode_steps``.

    ## Arguments
    ``gym.make("RollingDrive-v0", scene="default", render_mode=None, **overrides)``: ``scene``
    is a shipped scene name (``rolling_env.list_scenes()``), a path to a YAML file, a dict or a
    ``Scene``; ``overrides`` replace scene keys (``mu=0.1``, ``runner_mass=0.01``, ...) with the
    same validation; ``sub_steps=n``, ``resolution=r`` and ``grid_levels=L`` override the
    numerics (``accuracy=`` re-chooses "auto" sub-steps).  ``render_mode`` is ``"rgb_array"``
    (a uint8 frame of the contact and the
    runner against its target) or ``"human"`` (the same frame in a matplotlib window).

    ## Version History
    * v0: initial version.
    * v0, converged physics (same id, action mapping, observations, reward definition and
      scene physics; different transitions): the runner step is exact on the stuck contact
      (it was backward Euler, which damped the runner's ringing numerically); the wear term
      counts the elastic energy the material carries out at the trailing edge, where finite
      friction makes it slide to zero (it was released uncounted, so the wear was up to 2x
      low on coarse grids) and charges a sliding cell the mean of its friction limit over the
      sub-step; the shipped scenes take ``sub_steps: auto`` (from ``accuracy``) and 32 cells
      per contact radius on ``loaded``, ``resonant`` and ``light_stiff``.  Agents trained on
      the earlier transitions are evaluated as they are (results/comparison.md says so).
    * v0, level grid (same id, action mapping, observations, reward definition and scene
      physics; different transitions): the cells halve as the contact shrinks, so that every
      contact keeps more than half the cells per radius that the one at N_max has
      (``grid_levels``, default 4), with remaps that keep a linear deflection exactly; a
      load drop cuts the contact at the linear reconstruction of the cell holding its new
      end; ``light_stiff`` and ``heavy_inf_friction`` take 64 cells per contact radius.
    * v0, light_stiff's grid (same id, action mapping, observations, reward definition and
      scene physics; different transitions on ``light_stiff`` only): 128 cells per contact
      radius (182 sub-steps per tick from its accuracy), so that the Eq. 32 feedback design's
      episodes end within 0.1 tolerance of the converged runner position (0.17-0.21 at 64).
    * v0, slip work at the onset of sliding (same id, action mapping, observations, reward
      definition and scene physics; the same trajectories, a different wear term): a cell
      that starts a sub-step inside its friction limit is charged the limit over the part of
      the sub-step in which it slides (it was charged the mean over the whole sub-step, which
      left the Eq. 32 episodes' wear up to 1.6% high at the shipped sub-steps).
    * v0, sub-steps for the onset-charged wear (same id, action mapping, observations, reward
      definition and scene physics; different transitions on ``default``, ``loaded`` and
      ``resonant``): with finite friction "auto" takes half the sub-steps it took (12 on
      ``default``, 23 on ``loaded`` and ``resonant``), which the wear charged from the
      onset of sliding allows at unchanged accuracy; ``light_stiff`` keeps its 182 with
      ``accuracy: 0.0025``.
    * v0, sub-steps for bang-bang actions (same id, action mapping, observations, reward
      definition and scene physics; different transitions on ``default`` (and its randomised
      family), ``loaded`` and ``resonant``): with finite friction "auto" takes twice the
      sub-steps again (23 on
      ``default``, 46 on ``loaded`` and ``resonant``): with half as many, bang-bang actions
      (full-rate rolling reversals and load changes every tick) ended up to 0.27 tolerance
      from the converged runner position on ``default`` and 0.22 on ``resonant``.
      ``light_stiff`` keeps its 182, now at the default ``accuracy``.  A free runner's
      ringing is resolved at sqrt(accuracy) rad per sub-step (0.1 rad at the default; it
      was 0.22), which changes no shipped scene but gives a lighter runner more sub-steps
      (``light_stiff`` at half its mass: 236, was 211).
    * v0, resonant's grid (same id, action mapping, observations, reward definition and
      scene physics; different transitions on ``resonant`` only): 64 cells per contact
      radius with ``accuracy: 0.04`` (still 46 sub-steps per tick): a constant action,
      after which the runner rings on the stopped contact's edge microslip for the rest of
      the episode, ended up to 0.38 tolerance from the converged runner position at 32.
    * v0, default's grid (same id, action mapping, observations, reward definition and scene
      physics; different transitions on ``default`` and its randomised family only): 32
      cells per contact radius (46 sub-steps per tick from its accuracy).  At 16 the scene's
      own episodes ended within 0.1 tolerance of the converged runner position, but the
      same scene with one key changed (mu 1 or infinite, a load on the runner, longer
      ticks, a lighter runner) ended up to 0.74 tolerance off; at 32 within 0.23.
    * v0, finer grids (same id, action mapping, observations, reward definition and scene
      physics; different transitions on ``default`` (and its randomised family), ``loaded``
      and ``heavy_inf_friction``): ``default`` and ``loaded`` take 48 cells per contact
      radius with ``accuracy: 0.02`` (49 sub-steps per tick, as long as the 46 they took at
      32 cells); ``heavy_inf_friction`` takes 256 at its 29 sub-steps (with infinite
      friction "auto" counts the patch travel in cells of at least a_max / 64, which also
      gives any infinite-friction scene above 64 cells per radius fewer sub-steps).  With
      one key changed, ``default`` ended up to 0.23 tolerance from the converged runner
      position at 32 cells (0.17 at 48, mu = inf; the others within 0.07) and ``loaded`` up
      to 0.13 (at 48 within 0.07 but mu = inf, 0.20, and ticks twice as long, 0.13);
      ``heavy_inf_friction``'s bang-bang episodes (reset seeds 0-2) up to 0.49 at 64 cells,
      0.27 at 128 and 0.10 at 256.
    """

    metadata = {"render_modes": ["rgb_array", "human"], "render_fps": 30}

    def __init__(
        self, scene: str | dict | Scene = "default", render_mode: str | None = None, **overrides
    ):
        self.scene = load_scene(scene, **overrides)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(
                f"render_mode must be one of {self.metadata['render_modes']} or None,"
                f" got {render_mode!r}"
            )
        self.render_mode = render_mode
        self.action_space = spaces.Box(-1.0, 1.0, (3,), np.float32)
        self.observation_space = spaces.Box(-OBS_BOUND, OBS_BOUND, (len(OBS_NAMES),), np.float32)
        self.dt = self.scene.dt
        self._draw = {}  # this episode's draw of a randomised scene's physics
        self._build(self.scene)
        self._act = np.zeros((1, 3))
        self._target = np.zeros(1)
        self._steps = np.zeros(1, dtype=np.int64)
        self._out = np.zeros((1, K.N_OUT))
        self._obs = np.zeros((1, EK.N_OBS), dtype=np.float32)
        self._extra = np.zeros((1, EK.N_X))
        self._rew = np.zeros(1)  # the kernel's reward and truncation outputs
        self._trunc = np.zeros(1, dtype=np.bool_)
        self._history = []
        self._render_state = {}  # this env's figure and window (rolling_env.env.render)

    def _build(self, sc: Scene) -> None:
        """The drive and kernel constants for the physics of ``sc``; the observation and
        reward scales stay those of ``self.scene`` (the nominal scene of a randomised one), so
        that they mean the same in every episode."""
        self.drive, self.a_max = build_drive(sc)
        self._features = self.drive.kernel_features + (None,)  # no energy ledger
        self._sv = EK.scene_vector(sc, self.a_max, self.drive, scales=self.scene)
        self._bind_arrays()

    def _bind_arrays(self) -> None:
        """Batch-of-one views of the drive's arrays for the env kernel (made once, not per
        step: a view costs about as much as the rest of the step's Python layer)."""
        drv = self.drive
        self._arrays = (drv.cells[None], drv.st[None], drv._p[None])

    def __getstate__(self):
        # pickle and deepcopy would turn the views into independent copies: the kernel would
        # step them while reset() and render() use the drive's own arrays.  The figure and
        # window are left behind too (an unpickled matplotlib figure has no drawing canvas):
        # the copy draws its own at its first render()
        state = self.__dict__.copy()
        del state["_arrays"]
        state["_render_state"] = {}
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self._bind_arrays()

    @property
    def target(self) -> float:
        return float(self._target[0])

    # ------------------------------------------------------------------ gym API
    def reset(self, *, seed=None, options=None):
        given = target_option(self.scene, options)  # checked before anything changes
        super().reset(seed=seed)
        self._target[0] = sample_target(self.scene, self.np_random, given)
        if self.scene.randomize:  # this episode's physics, after the target's draw
            self._draw = draw_physics(self.scene, self.np_random)
            self._build(episode_scene(self.scene, self._draw))
        self.drive.reset()
        self._steps[0] = 0
        self._extra[:] = 0.0
        self._extra[0, EK.X_SAT] = 1.0
        EK.reset_obs(0, self._sv, self._target, self._obs)
        self._history = [0.0] if self.render_mode is not None else []
        return self._obs[0].copy(), self._info()

    def step(self, action):
        a = load_actions(action, (3,), self._act)
        W, st, p = self._arrays
        bad = EK.env_step_serial(
            self._act,
            self._sv,
            self._target,
            self._steps,
            W,
            st,
            p,
            self._out,
            self._obs,
            self._extra,
            self._rew,
            self._trunc,
            self.scene.episode_steps,
            *self._features,
        )
        if bad:
            raise_step_error(bad, a, (3,), st, self.scene)
        x = self._extra[0]
        if self.render_mode is not None:  # the runner's path, for the rendered frame only
            self._history.append(x[EK.X_XS])
            if self.render_mode == "human":
                self.render()
        return (self._obs[0].copy(), float(self._rew[0]), False, bool(self._trunc[0]), self._info())

    def render(self):
        if self.render_mode is None:
            gym.logger.warn("render() called without a render_mode; set render_mode='rgb_array'")
            return None
        from rolling_env.env.render import render_frame

        frame = render_frame(self, self._render_state)
        if self.render_mode == "human":
            from rolling_env.env.render import show

            show(frame, self._render_state)
            return None
        return frame

    def close(self):
        from rolling_env.env.render import close

        close(self._render_state)

    def _info(self) -> dict:
        d = info_dict(self._extra[0], self._target[0])
        if self._draw:
            d["scene_draw"] = dict(self._draw)
        return d


def build_drive(scene: Scene) -> tuple[Drive, float]:
    """The spring row of a scene: grid over the rolling stroke, a_ref = a_max = contact radius
    at N_max, time scale = the nominal period; without the energy ledger (the env kernel
    keeps none)."""
    sc = scene
    params = DriveParams(sc.R, sc.E_star, sc.G_star, mu=sc.mu, m=sc.runner_mass, F_ext=sc.F_ext)
    d_max = (3 * sc.N_max / (4 * sc.E_star * math.sqrt(sc.R))) ** (2 / 3)
    a_max = math.sqrt(sc.R * d_max)
    try:
        drive = Drive(
            params,
            a_ref=a_max,
            resolution=sc.resolution,
            stroke=(-sc.stroke_roll, sc.stroke_roll),
            a_max=a_max,
            t_ref=sc.period,
            ledger=False,
            levels=sc.grid_levels,
        )  # the env kernel keeps no ledger
    except ValueError as e:  # the Drive's message names its own arguments: map them to keys
        raise ValueError(
            f"scene '{sc.name}' cannot be built: {e} (the env builds the drive from the scene "
            f"keys: stroke = +-stroke_roll = {sc.stroke_roll:g} m, a_ref = a_max = the contact "
            f"radius at N_max = {sc.N_max:g} N ({a_max:.3g} m), resolution = "
            f"{sc.resolution:g}, levels = grid_levels = {sc.grid_levels}, t_ref = period = "
            f"{sc.period:g} s, m = runner_mass)"
        ) from None
    return drive, a_max


def check_time_limit(max_episode_steps, scene: Scene) -> int:
    """Episode length: the scene's ``episode_steps``, or a shorter ``max_episode_steps`` (an
    integer, or a float with an integer value); a longer one raises (the env ends episodes at
    ``episode_steps``), as do zero, negatives, non-integers, inf, NaN and booleans."""
    n = scene.episode_steps
    m = max_episode_steps
    if m is None:
        return n
    ok = (
        isinstance(m, numbers.Real)
        and not isinstance(m, (bool, np.bool_))
        and math.isfinite(m)
        and m == int(m)
    )
    if not ok or not 1 <= int(m) <= n:
        hint = (
            f"; pass episode_steps={int(m)} to lengthen episodes"
            if ok and n < int(m) <= EPISODE_STEPS_MAX
            else ""
        )
        raise ValueError(
            f"max_episode_steps must be an integer in [1, {n}] (the scene's "
            f"episode_steps{hint}), got {m!r}"
        )
    return int(m)


def target_option(scene: Scene, options, name: str = "options['target']") -> float | None:
    """The target [m] that ``reset(options=...)`` asks for, checked, or None to draw one.
    ``options`` is None or a dict whose only key is "target": a finite number with
    |target| <= OBS_BOUND target_max (beyond, the error observation would sit at its clip
    for the whole episode).  ``name``: what the error messages call the target."""
    if options is None:
        return None
    if not isinstance(options, Mapping):
        raise ValueError(
            f"options must be a dict (e.g. {{'target': 3e-7}}) or None, got {options!r}"
        )
    unknown = set(options) - {"target"}
    if unknown:
        raise ValueError(
            f"options has unknown key(s) {sorted(map(str, unknown))}; the only "
            "option is 'target' [m]"
        )
    if "target" not in options:
        return None
    t = options["target"]
    if isinstance(t, np.ndarray) and t.ndim == 0:
        t = t.item()  # a 0-d array is its number
    if isinstance(t, (bool, np.bool_)) or not isinstance(t, numbers.Real):
        raise ValueError(f"{name} must be a number [m], got {t!r}")
    lim = OBS_BOUND * scene.target_max
    try:
        t = float(t)
    except OverflowError:  # an integer beyond the float range (10**400)
        raise ValueError(
            f"{name} must be a finite displacement in [-{lim!r}, {lim!r}] m, got "
            f"an integer too large for a float"
        ) from None
    if not (math.isfinite(t) and abs(t) <= lim * (1.0 + 1e-12)):
        # the bound as the user reads it: 10 x 5e-7 rounds to 4.9999999999999996e-06, and
        # 5e-06 is admitted (its error observation sits at the clip, as the bound's does)
        raise ValueError(
            f"{name} must be a finite displacement in [-{lim:.6g}, "
            f"{lim:.6g}] m (OBS_BOUND x the scene's target_max, where the error "
            f"observation saturates), got {t!r}"
        )
    return t


def sample_target(scene: Scene, rng, given: float | None) -> float:
    """``given`` (from ``target_option``) if not None, else uniform in [target_min,
    target_max] with a random sign when target_both_signs, drawn from the env's generator."""
    if given is not None:
        return given
    mag = rng.uniform(scene.target_min, scene.target_max)
    # the draw rng.choice((-1.0, 1.0)) makes, without its conversion of the tuple to an
    # array (6.6 of the 9.5 us a batched env's reset took): the same generator state and
    # targets (compared on 2000 seeds), 1.1 us
    sign = (-1.0, 1.0)[rng.integers(0, 2)] if scene.target_both_signs else 1.0
    return float(sign * mag)


def load_actions(action, shape, dest) -> np.ndarray:
    """Copy actions of ``shape`` into the env kernel's float64 buffer ``dest``.  A wrong shape or
    a non-numeric type raises here (``check_actions`` names it); range and finiteness are
    checked in the kernel, which reports them through ``raise_step_error``."""
    a = check_action_dtype(action)
    if a.shape != shape:
        check_actions(a, shape)  # raises with the reason
    # a batch's actions already have the buffer's shape: a reshape would only add its cost
    # (0.3 of the 0.8 us this took for 256 envs)
    dest[...] = a if a.shape == dest.shape else a.reshape(dest.shape)
    return a


def check_action_dtype(action) -> np.ndarray:
    """``action`` as an array of real numbers (no complex, strings, objects or booleans)."""
    a = np.asarray(action)
    if a.dtype.kind not in "fiu":
        raise ValueError(f"action must be real numbers in [-1, 1], got dtype {a.dtype}: {action!r}")
    return a


def raise_step_error(bad: int, action, shape, st, scene: Scene | None = None, extra=None) -> None:
    """Raise what a nonzero status of the env kernel stands for: -1 a bad action (nothing was
    stepped), > 0 envs with a kernel error flag or a non-finite reward or velocity (with
    ``scene``, the error names the scene keys that can cause it).  For a batch (``extra``
    given, rows of ``st`` per env) the error names the envs that failed."""
    if bad < 0:
        check_actions(action, shape)  # raises with the reason
        raise ValueError("action must be finite and inside [-1, 1]")
    which = "" if extra is None else _failed_envs(st, extra)
    try:
        check_flags(st)
    except (RuntimeError, ValueError) as e:  # the grid flag; no equilibrium
        raise type(e)(f"{e}{which}") from None
    except FloatingPointError as e:
        raise FloatingPointError(f"{e}{_overflow_hint(scene)}{which}") from None
    # no flag raised: a non-finite reward or velocity
    raise FloatingPointError(f"non-finite state after a physics tick{_overflow_hint(scene)}{which}")


def _failed_envs(st, extra) -> str:
    """Which envs of a batch the kernel counted as failed (``_envkernel.mark_failed``), for
    the error message: every env was stepped, these are left in an invalid state."""
    failed = np.zeros(st.shape[0], dtype=np.int64)
    EK.mark_failed(st, extra, failed)
    bad = np.flatnonzero(failed).tolist()
    shown = ", ".join(map(str, bad[:10])) + (", ..." if len(bad) > 10 else "")
    return (
        f" (in {len(bad)} of the batch's {st.shape[0]} envs: {shown}; the others stepped "
        "normally; reset the failed ones, in gym.make_vec with "
        "reset(options={'reset_mask': mask}))"
    )


def _overflow_hint(scene: Scene | None) -> str:
    """What makes a legal scene overflow: a light runner under a load, free wherever the
    contact does not hold it (lift-off, sliding), gains velocity at |F_ext| / runner_mass."""
    if scene is None or scene.F_ext == 0.0 or not 0.0 < scene.runner_mass < math.inf:
        return ""
    acc = abs(scene.F_ext) / scene.runner_mass
    return (
        f"; the likely cause in this scene: a runner of runner_mass = "
        f"{scene.runner_mass:g} kg under F_ext = {scene.F_ext:g} N accelerates at "
        f"{acc:.3g} m/s^2 wherever the contact does not hold it, and its velocity or "
        "displacement leaves the floating-point range: raise runner_mass or lower |F_ext|"
    )


def check_actions(action, shape) -> np.ndarray:
    """Actions as float64 of ``shape``: finite and inside [-1, 1] (1e-6 tolerance), else
    ValueError."""
    a = np.asarray(action, dtype=np.float64)
    if a.shape != shape:
        raise ValueError(f"action must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"action must be finite, got {a.tolist()}")
    if np.any(np.abs(a) > 1.0 + 1e-6):
        raise ValueError(f"action must lie in [-1, 1] (the action space), got {a.tolist()}")
    return a


#: info key: column of the env kernel's extras (``_envkernel.EXTRA_NAMES`` less the reward)
INFO_COLUMNS = {k: i for i, k in enumerate(EK.EXTRA_NAMES) if k != "reward"}
_INFO_KEYS = tuple(INFO_COLUMNS)
# the info columns are one block of the extras, in the order of INFO_COLUMNS: the batched
# infos take them with one slice rather than a gather
_INFO_LO = min(INFO_COLUMNS.values())
_INFO_HI = _INFO_LO + len(INFO_COLUMNS)
if list(INFO_COLUMNS.values()) != list(range(_INFO_LO, _INFO_HI)):  # not an assert: kept under -O
    raise ImportError("rolling_env: INFO_COLUMNS must follow the order of _envkernel.EXTRA_NAMES")


def info_dict(x, target) -> dict:
    """The per-step info of one env from its row of the kernel's extras: the columns of
    ``INFO_COLUMNS`` plus target, error = target - x* and saturated = saturation < 1."""
    row = x.tolist()  # Python floats once; cheaper than a float() per entry
    d = {k: row[c] for k, c in INFO_COLUMNS.items()}
    t = float(target)
    d["target"] = t
    d["error"] = t - row[EK.X_XS]
    d["saturated"] = row[EK.X_SAT] < 1.0
    return d


def info_arrays(extra, target) -> dict:
    """``info_dict`` of every env as arrays (float64; saturated bool), one entry per env."""
    d = dict(zip(_INFO_KEYS, extra[:, _INFO_LO:_INFO_HI].T.copy()))  # one copy, rows as views
    d["target"] = np.array(target, dtype=np.float64)
    d["error"] = target - extra[:, EK.X_XS]
    d["saturated"] = extra[:, EK.X_SAT] < 1.0
    return d
