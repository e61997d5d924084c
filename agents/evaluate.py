"""Evaluate every controller on the same held-out targets and seeds, per scene.

    python -m agents.evaluate --scenes default resonant ... --runs runs/ --episodes 20

    python -m agents.evaluate --baselines-only --scenes default   # no trained agents needed

Controllers: the two Eq. 32 baselines and every trained agent under ``<runs>/<scene key>/*/``
(``common.scene_key``; each run checked to be trained on the scene's physics and task,
``check_run_scene``: one trained on other numerics of it is evaluated as it is and marked in
the tables, the CSV's ``trained_numerics`` and the plots)
(``agent_files``: the final model, or with ``--model best`` EvalCallback's best model when its
VecNormalize statistics were saved with it; an interrupted run's checkpoint where there is
neither; the statistics saved beside the model; a model whose statistics were saved at
another step is skipped with a warning for the next one; each row names the file used).
Writes ``results/comparison.md`` and ``results/comparison.csv`` (atomically) and plots under
``results/plots/``: learning curves per scene and one trajectory per controller on the same
target.  Runs of one configuration with several seeds (``<name>_seed<N>``) are also summed
up over the seeds (``seed_summary``).  Without ``--baselines-only`` a missing ``--runs`` folder,
or a scene without a trained agent there, is a usage error before anything is written (a
mistyped ``--runs`` replaced the committed table with a baselines-only one); so are a scene
given twice in ``--scenes`` (by scene key), a run folder named like a baseline, and a damaged
run file (config.yml, a model .zip, its VecNormalize statistics, meta.json, evaluations.npz:
one line naming the file).  ``--episodes`` is at most ``EPISODES_MAX``.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import re
import sys
import tempfile
from pathlib import Path

import numpy as np

import rolling_env
from rolling_env.cli import positive_int
from rolling_env.io import staged
from rolling_env.rollout import rollout

from .baselines import Eq32Design, Eq32Feedback, Eq32OpenLoop
from .common import SAVED_AT, atomic_write, buildable_scene, one_line, run_config, scene_key
from .verdicts import (  # noqa: F401  (re-exported: the tables' and the tests' names)
    BASELINES,
    goal_verdicts,
    marked,
    numerics_marks,
    one_configuration,
    seed_groups,
    time_to_goal,
)

EVAL_SEED = 20261122  # held out: training uses seeds < 1e6, evaluation envs seed + 10000
#: --episodes at most: an episode of a shipped scene (512 ticks) takes about 0.25 s per
#: controller on the 2-core machine, averaged over the shipped scenes (from heavy_inf_friction's
#: 8 sub-steps per tick to light_stiff's 75), so 1e5 episodes are about 7 hours per controller
#: and scene (1e9 built arrays until the process was killed for memory)
EPISODES_MAX = 10**5


class MismatchedStatistics(ValueError):
    """A model and VecNormalize statistics saved at different steps (a save interrupted
    between the two files): the run's next model may be used instead."""


def _load_error(path, e: BaseException) -> ValueError:
    """A file that the library failed to load (truncated, damaged, another format): one line
    naming the file, whatever torch, pickle or zipfile raised."""
    return ValueError(
        f"{str(path)!r} cannot be loaded: it is damaged or not what "
        f"agents.train writes ({one_line(e)})"
    )


class NormalizedAgent:
    """A trained SB3 model with its saved VecNormalize observation statistics applied."""

    def __init__(self, model, vecnorm=None):
        self.model = model
        self.vecnorm = vecnorm

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        if self.vecnorm is not None:
            obs = self.vecnorm.normalize_obs(np.asarray(obs))
        return self.model.predict(
            obs, state=state, episode_start=episode_start, deterministic=deterministic
        )


def model_algo(path) -> str:
    """The algorithm (``ppo``, ``sac``, ``td3``) that saved an SB3 model .zip, read from the
    zip's ``data`` JSON (the policy class's module and the algorithm's own saved attributes;
    nothing is unpickled).  A ValueError naming the file where it cannot be told."""
    import zipfile

    path = Path(path)
    try:
        with zipfile.ZipFile(path) as z:
            data = json.loads(z.read("data"))
    except (OSError, KeyError, zipfile.BadZipFile, ValueError) as e:
        raise ValueError(f"{str(path)!r} is not a Stable-Baselines3 model zip ({e})") from None
    module = (
        str((data.get("policy_class") or {}).get("__module__", ""))
        if isinstance(data.get("policy_class"), dict)
        else ""
    )
    for algo in ("sac", "td3", "ppo"):
        if module.startswith(f"stable_baselines3.{algo}."):
            return algo
    if "policy_delay" in data or "target_policy_noise" in data:
        return "td3"
    if "target_entropy" in data or "ent_coef_optimizer" in data:
        return "sac"
    if module == "stable_baselines3.common.policies" and {"clip_range", "n_epochs"} <= set(data):
        return "ppo"  # PPO's MlpPolicy is the common ActorCriticPolicy
    raise ValueError(
        f"cannot tell which algorithm saved {str(path)!r} (policy class module "
        f"{module or 'missing'!r}; this script loads PPO, SAC and TD3 models)"
    )


def load_agent(path, env=None, base_scene=None):
    """Load ``<name>.zip`` and, if beside it, ``<name>_vecnormalize.pkl`` (observation
    statistics applied, frozen): a ``NormalizedAgent``, or for a residual run (its config.yml
    names the baseline) a ``residual.ResidualAgent`` acting with its baseline, which is built
    for ``base_scene`` (default: the scene of ``env``, else the run's), or for a period-level
    run a ``period.PeriodAgent`` that decodes its working points on that scene too.
    The algorithm is read from the zip (``model_algo``) and checked against the run's
    config.yml where there is one.  A model without statistics is refused where its run's
    config.yml says the run normalised observations, and loaded with a warning where there is
    no config.yml to tell."""
    import stable_baselines3 as sb3
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from rolling_env.env import OBS_NAMES

    from .common import parse_kwargs
    from .period import N_ACTION as N_PERIOD_ACTION
    from .residual import N_BASE, ResidualAgent, ResidualVecEnv

    path = Path(path)
    cfg_path = path.parent / "config.yml"
    cfg = run_config(path.parent)  # None without one; a damaged one is a ValueError
    algo = model_algo(path)
    if cfg is not None and cfg.get("algo", algo) != algo:
        raise ValueError(
            f"{path.name} was saved by {algo.upper()} but {cfg_path} says algo "
            f"{cfg.get('algo')!r}: the model does not belong to this run"
        )
    cls = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]
    try:
        model = cls.load(path, device="cpu")
    except Exception as e:  # noqa: BLE001  (a damaged policy.pth: torch's RuntimeError, ...)
        raise _load_error(path, e) from None
    stats = path.with_name(path.stem + "_vecnormalize.pkl")
    vecnorm = None
    residual = _residual_of(cfg, path)
    width = getattr(model.observation_space, "shape", (0,))[0]
    if residual is None and width == len(OBS_NAMES) + N_BASE:
        raise ValueError(
            f"{path} takes {width} observations: it is a residual agent (the env's "
            f"{len(OBS_NAMES)} and its baseline's action), and the config.yml of "
            "its run, which names the baseline, is not beside it"
        )
    period = _period_of(cfg, path)
    n_act = getattr(model.action_space, "shape", (0,))[0]
    if not period and n_act == N_PERIOD_ACTION:
        raise ValueError(
            f"{path} acts with {n_act} numbers: it is a period-level agent (an Eq. 32 "
            "working point per period), and the config.yml of its run, which says so, is "
            "not beside it"
        )
    if stats.exists():
        scene = env.unwrapped.scene if env is not None else "default"
        venv = DummyVecEnv([lambda: rolling_env.make(scene)])
        if residual is not None:  # the statistics are of the augmented observation
            venv = ResidualVecEnv(venv, *residual)
        try:
            vecnorm = VecNormalize.load(str(stats), venv)
        except Exception as e:  # noqa: BLE001  (truncated: UnpicklingError, EOFError, ...)
            raise _load_error(stats, e) from None
        if not isinstance(vecnorm, VecNormalize):  # another object pickled under the name
            raise _load_error(stats, TypeError(f"holds a {type(vecnorm).__name__}"))
        saved_at = getattr(vecnorm, SAVED_AT, None)  # absent in files saved before the tag
        if saved_at is not None and saved_at != model.num_timesteps:
            raise MismatchedStatistics(
                f"{stats.name} was saved at step {saved_at} but {path.name} at step "
                f"{model.num_timesteps} (a save interrupted between the two files): they do "
                "not belong together; use another model of the run"
            )
        vecnorm.training = False
        vecnorm.norm_reward = False
    elif cfg is not None:
        try:
            norm = parse_kwargs(cfg.get("normalize", False))
        except ValueError:
            norm = {}
        if norm is not None and norm.get("norm_obs", True):
            raise ValueError(
                f"{path} has no {stats.name} beside it, but its run normalised "
                "observations (config.yml): without the statistics the agent "
                "would act on raw observations"
            )
    else:
        print(
            f"warning: {path} has no {stats.name} beside it and no config.yml: observations "
            "are fed unnormalised; if the run used VecNormalize (agents.train does by "
            "default), copy its statistics beside the model",
            file=sys.stderr,
        )
    agent = NormalizedAgent(model, vecnorm)
    if residual is None and not period:
        return agent
    # the baseline, or the decoding of a period action, of the scene the agent knows
    scene = (
        base_scene
        if base_scene is not None
        else (env.unwrapped.scene if env is not None else _trained_scene(cfg))
    )
    if residual is not None:
        return ResidualAgent(agent, *residual, scene)
    from .period import PeriodAgent

    return PeriodAgent(agent, scene)


def _residual_of(cfg: dict | None, path: Path):
    """(base, scale) of a residual run from its config.yml, None for a plain one."""
    if not cfg or cfg.get("residual") is None:
        return None
    from .residual import SCALE_DEFAULT, check_residual

    try:
        return check_residual(cfg["residual"], cfg.get("residual_scale", SCALE_DEFAULT))
    except ValueError as e:
        raise ValueError(f"{path.parent / 'config.yml'}: {e}") from None


def _period_of(cfg: dict | None, path: Path) -> bool:
    """Whether a run's config.yml says it decides once per period (checked as agents.train
    checks the key)."""
    if not cfg:
        return False
    from .period import check_period_actions

    try:
        return check_period_actions(cfg.get("period_actions", False))
    except ValueError as e:
        raise ValueError(f"{path.parent / 'config.yml'}: {e}") from None


def _trained_scene(cfg: dict):
    """The scene a run was trained on, from its config.yml."""
    from rolling_env.scenes import load_scene

    extra = {k: v for k, v in dict(cfg.get("env_kwargs") or {}).items() if k != "scene"}
    return load_scene(cfg.get("scene", "default"), **extra)


#: which model of a run ``--model`` evaluates: the final one (``model.zip``, RL Zoo's default)
#: or EvalCallback's best (``best_model.zip``, selected on the training script's own eval env,
#: never on the held-out targets here)
MODELS = ("final", "best")


def agent_files(run: Path, model: str = "final") -> list[Path]:
    """The models of a run in the order they are tried.  ``model`` "final": the final model,
    then an interrupted run's checkpoint; "best": EvalCallback's best model when its
    VecNormalize statistics were saved with it, then those two.  The file used is recorded in
    each row (``model_file``), so a fallback is never reported as the kind asked for."""
    if model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {model!r}")
    files = []
    best = run / "best_model.zip"
    if model == "best" and best.exists() and (run / "best_model_vecnormalize.pkl").exists():
        files.append(best)
    return files + [run / n for n in ("model.zip", "checkpoint.zip") if (run / n).exists()]


def agent_file(run: Path, model: str = "final") -> Path | None:
    """The first of ``agent_files`` (None for a run without a model)."""
    files = agent_files(run, model)
    return files[0] if files else None


def held_out_targets(scene, n: int) -> list[float]:
    """n targets drawn from the scene's range with a fixed seed (the same for every controller)."""
    sc = rolling_env.scenes.load_scene(scene)
    rng = np.random.default_rng(EVAL_SEED)
    mags = rng.uniform(sc.target_min, sc.target_max, n)
    signs = rng.choice([-1.0, 1.0], n) if sc.target_both_signs else np.ones(n)
    return (mags * signs).tolist()


def episode_metrics(data: dict, tol: float) -> dict:
    e = np.abs(data["error"])
    inside = e <= tol
    if inside[-1]:
        last_out = np.nonzero(~inside)[0]
        k = 0 if last_out.size == 0 else last_out[-1] + 1
        t_settle = float(data["t"][k]) if k < len(e) else float(data["t"][-1])
    else:
        t_settle = float("nan")
    return {
        "final_abs_error": float(e[-1]),
        "rms_error": float(np.sqrt(np.mean(e**2))),
        "settle_time": t_settle,
        "slip_work": float(data["total_slip_work"]),
        "return": float(data["return"]),
    }


def _stem(scene) -> str:
    p = Path(str(scene))
    return p.stem if p.suffix.lower() in (".yaml", ".yml") else str(scene)


def load_checked_agent(path, env, scene=None):
    """A model .zip trained by agents.train, for ``env``: its run folder's scene checked
    against ``scene`` (default the env's) by content (a copy of a scene under another name is
    fine), then ``load_agent``.  Registered as the ``sb3`` model loader of ``rolling-drive
    rollout`` (entry-point group ``rolling_drive.model_loaders``, pyproject.toml)."""
    check_run_scene(
        Path(path).parent, env.unwrapped.scene if scene is None else scene, by_key=False
    )
    return load_agent(path, env)


def check_run_scene(run: Path, scene, by_key: bool = True) -> str:
    """Refuse a run that was not trained on ``scene``'s physics and task: scene overrides in
    its env_kwargs (an agent trained with mu = 0.02 would be reported as if trained on the
    plain scene), scene content (``common.scene_fields``, recorded with their digest by
    agents.train) other than ``scene``'s in any key but the numerics (``NUMERICS_KEYS``), and
    with ``by_key`` (evaluate: runs are tabulated by key) another scene key (a scene file
    whose stem names a shipped scene but whose content differs has its own key,
    ``common.scene_key``).  A run whose recorded scene differs only in its numerics
    (sub-steps, resolution, accuracy: the same physics and task, integrated otherwise) is
    evaluated as it is: the return value says what differs (``common.numerics_note``; "" where
    nothing does) and a warning is printed.  The recorded fields are compared key by key only
    where they reproduce the recorded digest; otherwise any digest difference refuses the
    run.  A run without a config.yml is not checked; one from before the digest was recorded
    is checked by the scene's name, with a warning."""
    from rolling_env.scenes import Scene

    from .common import (
        NUMERICS_KEYS,
        REWARD_KEYS,
        completed_fields,
        differing_fields,
        fields_digest,
        numerics_note,
        scene_fields,
        scene_key,
    )

    cfg = run_config(run)  # a damaged config.yml: a ValueError naming it
    if cfg is None:
        return ""
    trained = cfg.get("scene")
    digest = cfg.get("scene_digest")
    trained_key = cfg.get("scene_key", None if trained is None else _stem(trained))
    if (by_key or digest is None) and trained_key is not None and not isinstance(scene, Scene):
        key = scene_key(scene) if "scene_key" in cfg else _stem(scene)
        if str(trained_key) != key:
            raise ValueError(
                f"run {str(run)!r} was trained on scene {trained_key!r} "
                f"({trained}), not {key!r}: use it on its own scene (evaluate "
                f"looks for it under <runs>/{trained_key}/)"
            )
    name = scene.name if isinstance(scene, Scene) else str(scene)
    extra = {
        k: v
        for k, v in dict(cfg.get("env_kwargs") or {}).items()
        if k != "scene" and k not in REWARD_KEYS
    }
    if extra:
        raise ValueError(
            f"run {str(run)!r} was trained with scene overrides {extra}: it is not "
            f"comparable on the plain scene {name!r}; put the overrides in a "
            "scene file, train on it and evaluate that scene"
        )
    if digest is None:
        print(
            f"warning: {run}/config.yml records no scene_digest (an older run): its scene "
            f"is checked by name only",
            file=sys.stderr,
        )
        return ""
    now = scene_fields(scene)
    if digest == fields_digest(now):
        return ""
    recorded = dict(cfg.get("scene_fields") or {})
    trusted = bool(recorded) and fields_digest(recorded) == digest
    full = completed_fields(recorded) if trusted else recorded
    differ = [k for k in set(full) | set(now) if full.get(k, "-") != now.get(k, "-")]
    if not trusted or any(k not in NUMERICS_KEYS + REWARD_KEYS for k in differ):
        diff = differing_fields(full, now)
        raise ValueError(
            f"run {str(run)!r} was trained on a scene whose content differs from "
            f"{name!r} (trained vs now: {diff or 'scene digest differs'}): not "
            "comparable"
        )
    note = numerics_note(full, now)
    if note:
        print(
            f"warning: {run} was trained on other numerics or reward weights of scene "
            f"{name!r} ({note}; the "
            "physics and task keys are equal): it is evaluated as it is, on the scene's "
            "numerics as they are now",
            file=sys.stderr,
        )
    return note


def scene_runs(scene: str, runs: Path | None) -> list[Path]:
    """The run folders of a scene: ``<runs>/<scene key>/*/`` (the training script's layout;
    the key of a scene file is its stem); none when ``runs`` is None (baselines only).
    Hidden folders (an earlier run ``agents.train --overwrite`` could not delete) and
    ``*.overwrite`` folders (a replacement run that failed or was stopped) are not runs."""
    if runs is None:
        return []
    return sorted(
        (
            p
            for p in (runs / scene_key(scene)).glob("*")
            if p.is_dir() and not p.name.startswith(".") and not p.name.endswith(".overwrite")
        ),
        key=_natural,
    )


def _natural(path: Path) -> list:
    """Sort key that orders numbers by value: ppo_seed2 before ppo_seed10."""
    return [int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path.name)]


def controllers_for(scene: str, runs: Path | None, env, model: str = "final") -> dict:
    """The two baselines and every run's agent (``model``: which of its models, see
    ``agent_files``; each run checked to be trained on ``scene``, ``check_run_scene``: what
    differs in the numerics it was trained on is the agent's ``numerics``; its meta.json and
    evaluations.npz read); ``runs`` None: the baselines alone.  A run
    folder named like a baseline is refused (it would replace the baseline's row); a damaged
    file of a run is a ValueError naming it, before any episode runs."""
    ctrls = {
        "eq32-open-loop": Eq32OpenLoop.from_env(env),
        "eq32-feedback": Eq32Feedback.from_env(env),
    }
    for run in scene_runs(scene, runs):
        files = agent_files(run, model)
        if not files:
            print(
                f"warning: {run} has no model (model.zip, checkpoint.zip or, with --model "
                "best, best_model.zip): it is not evaluated (its learning curve is plotted)",
                file=sys.stderr,
            )
        else:
            if run.name in BASELINES:
                raise ValueError(
                    f"run folder {str(run)!r} has the name of a baseline: rename "
                    "it (its row would replace the baseline's)"
                )
            numerics = check_run_scene(run, scene)
            _budget(run)
        learning_curve(run)  # plotted for every run folder of the scene
        for k, path in enumerate(files):
            try:
                agent = load_agent(path, env)
            except MismatchedStatistics as e:  # a pair that does not belong together
                if k == len(files) - 1:
                    raise
                print(f"warning: {run}: {e}; trying {files[k + 1].name}", file=sys.stderr)
                continue
            agent.file, agent.run, agent.numerics = path.name, run, numerics
            ctrls[run.name] = agent
            break
    return ctrls


MACHINE = "2-core x86_64 CPU, no GPU"


def evaluate_scene(
    scene: str, runs: Path, episodes: int, env=None, ctrls: dict | None = None, model: str = "final"
) -> tuple[list[dict], dict]:
    """Every controller on the scene's held-out targets (episode i: target i, seed
    EVAL_SEED + i).  Returns one row per controller and the trajectory of target 0 of each.
    ``env`` and ``ctrls`` (from ``controllers_for``) are built here when not given."""
    env = env if env is not None else rolling_env.make(scene)
    ctrls = ctrls if ctrls is not None else controllers_for(scene, runs, env, model)
    tol = env.unwrapped.scene.tolerance
    targets = held_out_targets(scene, episodes)
    rows, trajectories = [], {}
    for name, ctrl in ctrls.items():
        per = []
        for i, target in enumerate(targets):
            data = rollout(env, ctrl, seed=EVAL_SEED + i, target=target)
            per.append(episode_metrics(data, tol))
            if i == 0:
                trajectories[name] = data
        row = {
            "scene": scene_key(scene),
            "controller": name,
            "model_file": getattr(ctrl, "file", "-"),
            "episodes": len(per),
            "episode_steps": env.unwrapped.scene.episode_steps,
            "episode_seconds": env.unwrapped.scene.episode_steps * env.unwrapped.scene.dt,
        }
        for key in ("final_abs_error", "slip_work"):  # per episode, for the statistics
            row[f"episode_{key}"] = [float(p[key]) for p in per]
        for key in ("final_abs_error", "rms_error", "slip_work", "return"):
            vals = np.array([p[key] for p in per])
            row[f"{key}_mean"] = float(vals.mean())
            row[f"{key}_std"] = float(vals.std())
        settle = np.array([p["settle_time"] for p in per])
        row["reached_fraction"] = float(np.mean(np.isfinite(settle)))
        row["settle_time_mean"] = (
            float(np.nanmean(settle)) if np.any(np.isfinite(settle)) else float("nan")
        )
        row["tolerance"] = tol
        row.update(_budget(getattr(ctrl, "run", None)))
        row["config_key"] = _config_key(getattr(ctrl, "run", None))
        row["goal_log"] = read_goal_log(getattr(ctrl, "run", None))
        row["trained_numerics"] = getattr(ctrl, "numerics", "")  # "" where trained on these
        rows.append(row)
    env.close()
    return rows, trajectories


def _config_key(run: Path | None) -> str | None:
    """A run's config.yml less its seed, as one string (``seed_summary`` sums up over seeds
    only the runs whose configurations are equal); None without one."""
    cfg = run_config(run) if run is not None else None
    if cfg is None:
        return None
    return json.dumps({k: v for k, v in cfg.items() if k != "seed"}, sort_keys=True, default=str)


def _budget(run: Path | None) -> dict:
    """The training budget from a run's meta.json (none without one); a ValueError naming
    the file where it is damaged."""
    import math

    meta = run / "meta.json" if run is not None else None
    if meta is None or not meta.exists():
        return {"train_env_steps": 0, "train_wall_seconds": 0.0, "machine": "-"}
    try:
        m = json.loads(meta.read_text(encoding="utf-8"))
        steps, wall = m["env_steps"], m["wall_seconds"]
        ok = (
            isinstance(steps, int)
            and not isinstance(steps, bool)
            and steps >= 0
            and isinstance(wall, (int, float))
            and not isinstance(wall, bool)
            and math.isfinite(wall)
            and wall >= 0
        )
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ValueError(
            f"{str(meta)!r} cannot be read: it is damaged or not what "
            f"agents.train writes ({one_line(e)})"
        ) from None
    if not ok:
        raise ValueError(
            f"{str(meta)!r}: env_steps must be an integer >= 0 and wall_seconds "
            f"a number >= 0, got {steps!r} and {wall!r}"
        )
    return {"train_env_steps": steps, "train_wall_seconds": round(wall, 1), "machine": MACHINE}


def learning_curve(run: Path):
    """``(env steps, mean, std)`` of the run's EvalCallback log (``evaluations.npz``), None
    without one; a ValueError naming the file where it is damaged."""
    ev = run / "evaluations.npz"
    if not ev.exists():
        return None
    try:
        with np.load(ev) as d:
            steps, res = np.asarray(d["timesteps"], float), np.asarray(d["results"], float)
        if res.ndim != 2 or steps.shape != res.shape[:1]:
            raise ValueError(f"timesteps {steps.shape} and results {res.shape} do not match")
    except Exception as e:  # noqa: BLE001  (zipfile, pickle, numpy: a damaged file)
        raise _load_error(ev, e) from None
    return steps, res.mean(axis=1), res.std(axis=1)


COLS = [
    "scene",
    "controller",
    "model_file",
    "episodes",
    "tolerance",
    "final_abs_error_mean",
    "final_abs_error_std",
    "rms_error_mean",
    "rms_error_std",
    "reached_fraction",
    "settle_time_mean",
    "slip_work_mean",
    "slip_work_std",
    "return_mean",
    "return_std",
    "train_env_steps",
    "train_wall_seconds",
    "machine",
    "trained_numerics",
]


def read_goal_log(run: Path | None):
    """A run's ``eval_goal.json`` (agents.train's periodic evaluations: env steps, wall time,
    each episode's final |error| and slip work); None without one."""
    from .train import GOAL_LOG

    path = run / GOAL_LOG if run is not None else None
    if path is None or not path.exists():
        return None
    try:
        log = json.loads(path.read_text(encoding="utf-8"))
        for e in log:
            int(e["env_steps"]), float(e["wall_seconds"])
            np.asarray(e["final_abs_error"], float), np.asarray(e["slip_work"], float)
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise ValueError(
            f"{str(path)!r} cannot be read: it is damaged or not what "
            f"agents.train writes ({one_line(e)})"
        ) from None
    return log


def _fmt_time_to_goal(t) -> str:
    if t is None:
        return "not logged"
    return t if isinstance(t, str) else f"{t[0]:,}, {t[1]:.0f}"


def seed_summary(rows: list[dict]) -> list[dict]:
    """Per scene, the agents that differ only in their seed (run folders ``<name>_seed<N>``,
    agents.train's default) summed up over the seeds, for each name with two runs or more:
    the mean over seeds of each run's mean final |error| and slip work, the smallest and
    largest run mean, and in how many seeds the goal (``goal_verdicts``) is met.  Runs of one
    name whose configurations (config.yml less the seed), model files or training steps
    differ (an interrupted run's checkpoint, another budget) are not summed up: a warning
    says so.  One seed says little about an RL algorithm; this is the row to read where there
    are several."""
    verdicts = {(v["scene"], v["agent"]): v for v in goal_verdicts(rows)}
    out = []
    for (scene, name), members in seed_groups(rows).items():
        if len(members) < 2:
            continue
        rs = [r for r, _ in members]
        seeds = [seed for _, seed in members]
        if not one_configuration(rs) or len(set(seeds)) < len(seeds):
            print(
                f"warning: {scene}: {', '.join(r['controller'] for r in rs)} are not summed "
                "up over seeds: their configurations (config.yml less the seed), model files "
                "or training steps differ, or two of them name one seed",
                file=sys.stderr,
            )
            continue
        err = np.array([r["final_abs_error_mean"] / r["tolerance"] for r in rs])
        slip = np.array([r["slip_work_mean"] for r in rs])
        met = [
            verdicts[(scene, r["controller"])]["met"]
            for r in rs
            if (scene, r["controller"]) in verdicts
        ]
        out.append(
            {
                "scene": scene,
                "agent": name,
                "seeds": len(rs),
                "seed_list": sorted(seeds),
                "runs": [r["controller"] for r in rs],
                "error_mean": float(err.mean()),
                "error_min": float(err.min()),
                "error_max": float(err.max()),
                "slip_mean": float(slip.mean()),
                "slip_min": float(slip.min()),
                "slip_max": float(slip.max()),
                "met": sum(met),
                "judged": len(met),
            }
        )
    return out


def _fmt_ratio(r: float) -> str:
    return "both 0" if np.isnan(r) else ("inf" if np.isinf(r) else f"{r:.2f}")


def _fmt_settle(st: float) -> str:
    return "never" if not np.isfinite(st) else f"{st * 1e3:.2f}"


def write_tables(
    rows: list[dict], out: Path, episodes: int | None = None, model: str = "final"
) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLS, extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    atomic_write(out / "comparison.csv", lambda p: Path(p).write_text(buf.getvalue()))
    n = episodes or (rows[0]["episodes"] if rows else 0)
    lengths = sorted(
        {(r.get("episode_steps"), r.get("episode_seconds")) for r in rows if r.get("episode_steps")}
    )
    length = (
        "; ".join(f"{k} ticks = {t * 1e3:.3g} ms" for k, t in lengths)
        or "the scene's episode_steps"
    )
    marks = numerics_marks(rows)
    note_of = {(r["scene"], r["controller"]): r.get("trained_numerics") or "" for r in rows}
    lines = [
        "# Controllers compared on held-out targets",
        "",
        "Generated by `python -m agents.evaluate` (see docs/agents.md).  Per scene every "
        "controller "
        f"runs the same {n} held-out targets (drawn with seed {EVAL_SEED} from the "
        "scene's target range; episode i uses env seed "
        f"{EVAL_SEED} + i), one episode each ({length}).  Errors in units of the "
        "scene's tolerance; RMS over the whole episode (tracking); *reached* = share of "
        "episodes that end within the tolerance; *settle* = mean time after which "
        "|error| stays within the tolerance (over the episodes that reach it; 'never' if "
        "none does); slip work = friction work of the episode (wear), mean over episodes, "
        "in nJ (0 with mu = inf).  Training budget: env steps and wall time of the run on "
        f"the {MACHINE} (shared with concurrent jobs); baselines need none.  Agents: "
        + (
            "the final model of each run (`--model final`)"
            if model == "final"
            else "EvalCallback's best model of each run where it has one with its statistics, "
            "else its final model or checkpoint (`--model best`)"
        )
        + "; *model* names the file evaluated."
        + (
            "  Agents marked [k] were trained on their scene with other numerics (the "
            "keys sub_steps, resolution, accuracy and grid_levels, which set how finely the env "
            "integrates the same physics; the notes below the table say what differed) and "
            "the same physics and task keys: they are evaluated as they are, not retrained, "
            "on the scene's numerics as they are now, like the baselines."
            if marks
            else ""
        ),
        "",
        "| scene | controller | model | final abs error / tol (mean ± std) | RMS error / "
        "tol | reached | settle [ms] | slip work [nJ] (mean ± std) | training (env steps, "
        "wall s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        tol = r["tolerance"]
        name = marked(r["controller"], note_of[(r["scene"], r["controller"])], marks)
        budget = (
            f"{r['train_env_steps']:,}, {r['train_wall_seconds']:.0f}"
            if r["train_env_steps"]
            else "-"
        )
        lines.append(
            f"| {r['scene']} | {name} | {r.get('model_file', '-')} | "
            f"{r['final_abs_error_mean'] / tol:.2f} ± "
            f"{r['final_abs_error_std'] / tol:.2f} | {r['rms_error_mean'] / tol:.1f} | "
            f"{100 * r['reached_fraction']:.0f}% | {_fmt_settle(r['settle_time_mean'])} | "
            f"{r['slip_work_mean'] * 1e9:.3g} ± {r['slip_work_std'] * 1e9:.2g} | {budget} |"
        )
    if marks:
        lines += [""] + [
            f"* [{k}] trained on other numerics or reward weights: {note}"
            for note, k in marks.items()
        ]
    verdicts = goal_verdicts(rows)
    if verdicts:
        lines += [
            "",
            "## The goal: at most half the best baseline's final error at no more slip work",
            "",
            "Best baseline = the Eq. 32 controller with the lower mean final error in the scene.",
            "",
            "*First met in training* (indicative): the env steps and wall seconds at "
            "which a periodic evaluation of the run (agents.train's: a few episodes on "
            "targets of its own, not these) first met the goal against this baseline's "
            "numbers above, so it can disagree with *met*; 'not logged' for runs from "
            "before the log.",
            "",
            "| scene | agent | best baseline | final error agent / baseline | "
            "slip work agent / baseline | met | first met in training (env steps, "
            "wall s) |",
            "|---|---|---|---|---|---|---|",
        ]
        for v in verdicts:
            sr = v["slip_ratio"]
            agent = marked(v["agent"], note_of.get((v["scene"], v["agent"]), ""), marks)
            lines.append(
                f"| {v['scene']} | {agent} | {v['baseline']} | "
                f"{v['error_ratio']:.2f} | {_fmt_ratio(sr)}"
                f" | {'yes' if v['met'] else 'no'} | "
                f"{_fmt_time_to_goal(v['time_to_goal'])} |"
            )
    summary = seed_summary(rows)
    if summary:
        lines += [
            "",
            "## Over seeds",
            "",
            "Agents trained with the same configuration and different seeds "
            "(`<name>_seed<N>`): the mean over the seeds of each run's mean, with the "
            "smallest and largest run mean, and in how many seeds the goal above is met.",
            "",
            "| scene | agent | seeds | final abs error / tol: mean over seeds (min-max) "
            "| slip work [nJ]: mean over seeds (min-max) | goal met |",
            "|---|---|---|---|---|---|",
        ]
        for g in summary:
            seeds = ", ".join(str(k) for k in g["seed_list"])
            agent = marked(g["agent"], [note_of.get((g["scene"], c), "") for c in g["runs"]], marks)
            lines.append(
                f"| {g['scene']} | {agent} | {seeds} | {g['error_mean']:.2f} "
                f"({g['error_min']:.2f}-{g['error_max']:.2f}) | "
                f"{g['slip_mean'] * 1e9:.3g} ({g['slip_min'] * 1e9:.3g}-"
                f"{g['slip_max'] * 1e9:.3g}) | {g['met']} of {g['judged']} |"
            )
    if any(r["controller"] not in BASELINES for r in rows) and all(
        "episode_final_abs_error" in r for r in rows
    ):
        from . import stats as S

        st = S.seed_statistics(rows)
        lines += [""] + S.markdown(st, marks)
        (out / "plots").mkdir(parents=True, exist_ok=True)
        S.plot_intervals(st, out / "plots" / "intervals.png")
        lines += ["", "![IQM final error with 95% intervals](plots/intervals.png)"]
        write_episodes(rows, out / "comparison_episodes.csv")
    atomic_write(out / "comparison.md", lambda p: Path(p).write_text("\n".join(lines) + "\n"))


def write_episodes(rows: list[dict], path: Path) -> None:
    """Every controller's per-episode final |error| / tolerance and slip work [J]: the data
    of the statistics over seeds and targets."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["scene", "controller", "episode", "final_abs_error_tol", "slip_work"])
    for r in rows:
        for i, (e, sw) in enumerate(zip(r["episode_final_abs_error"], r["episode_slip_work"])):
            w.writerow([r["scene"], r["controller"], i, repr(e / r["tolerance"]), repr(sw)])
    atomic_write(path, lambda p: Path(p).write_text(buf.getvalue()))


def plot_scene(
    scene: str,
    runs: Path,
    trajectories: dict,
    out: Path,
    notes: dict | None = None,
    marks: dict | None = None,
) -> Path:
    """results/plots/<scene>.png: the runner on held-out target 0 for every controller, its
    |error| / tolerance (log), and the learning curves (EvalCallback) of the scene's runs.
    ``notes``: controller -> what differed in the numerics it was trained on
    (``trained_numerics``), shown with the tables' footnote numbers ``marks``
    (``numerics_marks``; numbered here where not given) in the legends and under the plot."""
    notes = {k: v for k, v in (notes or {}).items() if v}
    if marks is None:
        marks = numerics_marks([{"trained_numerics": n} for n in notes.values()])
    labels = {name: marked(name, note, marks) for name, note in notes.items()}
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tol = rolling_env.scenes.load_scene(scene).tolerance
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.2))
    colors = {name: f"C{i % 10}" for i, name in enumerate(trajectories)}  # one per controller,
    # the same in every panel
    for name, data in trajectories.items():
        ls = "--" if name in BASELINES else "-"
        label = labels.get(name, name)
        ax[0].plot(data["t"] * 1e3, data["xstar"] * 1e9, ls, label=label, color=colors[name])
        ax[1].semilogy(
            data["t"] * 1e3,
            np.maximum(np.abs(data["error"]) / tol, 1e-3),
            ls,
            label=label,
            color=colors[name],
        )
    first = next(iter(trajectories.values()))
    ax[0].plot(first["t"] * 1e3, first["target"] * 1e9, "k:", label="target")
    ax[0].set(
        xlabel="t [ms]",
        ylabel="runner x* [nm]",
        title=f"{scene}: held-out target {first['target'][0] * 1e9:.0f} nm",
    )
    ax[0].legend(fontsize=7)
    ax[1].axhline(1.0, color="k", lw=0.8)
    ax[1].set(
        xlabel="t [ms]",
        ylabel="|error| / tolerance",
        ylim=(1e-2, None),
        title="tracking error (line: tolerance)",
    )
    for run in scene_runs(scene, runs):
        curve = learning_curve(run)
        if curve is not None:
            steps, mean, std = curve
            color = colors.get(run.name, "0.5")  # grey: a run without a model
            ax[2].plot(steps, mean, label=labels.get(run.name, run.name), color=color)
            ax[2].fill_between(steps, mean - std, mean + std, alpha=0.2, color=color)
    ax[2].set(
        xlabel="env steps",
        ylabel="eval return (mean ± std over episodes)",
        title="learning curves (EvalCallback)",
    )
    if ax[2].lines:
        ax[2].legend(fontsize=7)
    else:  # --baselines-only, or runs without an EvalCallback log: say so, not a blank panel
        ax[2].text(
            0.5,
            0.5,
            "no learning curves\n(baselines only, or no evaluations.npz)",
            ha="center",
            va="center",
            transform=ax[2].transAxes,
            fontsize=9,
        )
    fig.tight_layout()
    shown = sorted({marks[n]: n for n in notes.values()}.items())
    if shown:  # which numerics the marked agents were trained on, under the panels
        fig.subplots_adjust(bottom=0.2)
        fig.text(
            0.01,
            0.01,
            "; ".join(
                f"[{k}] trained with other numerics or reward weights: {n}" for k, n in shown
            ),
            fontsize=8,
            va="bottom",
        )
    path = atomic_write(
        out / "plots" / f"{scene_key(scene)}.png", lambda p: fig.savefig(p, dpi=80, format="png")
    )
    plt.close(fig)
    return path


def main(argv=None):
    p = argparse.ArgumentParser(
        prog="python -m agents.evaluate", description=__doc__.splitlines()[0]
    )
    p.add_argument(
        "--scenes",
        nargs="+",
        default=rolling_env.list_scenes(),
        help="scene names or YAML paths (default: every shipped scene)",
    )
    p.add_argument("--runs", default="runs", help="folder of training runs (<runs>/<scene>/<run>/)")
    p.add_argument(
        "--episodes",
        type=positive_int("episodes", 1, EPISODES_MAX),
        default=20,
        help=f"held-out targets per scene, 1 to {EPISODES_MAX:,} (an episode takes "
        "about 0.25 s per controller on the shipped scenes; default 20)",
    )
    p.add_argument(
        "--out",
        default="results",
        help="output folder of comparison.md, .csv and plots/ (default results, "
        "relative to the current directory)",
    )
    p.add_argument(
        "--model",
        choices=MODELS,
        default="final",
        help="which model of each run: final (model.zip, default) or best "
        "(EvalCallback's best_model.zip, selected on the training run's own eval "
        "env); the table names the file each row used",
    )
    p.add_argument(
        "--baselines-only",
        action="store_true",
        help="compare the two Eq. 32 baselines alone (no --runs needed); without it "
        "every scene must have a trained agent under <runs>/<scene key>/",
    )
    args = p.parse_args(argv)
    keys = {}
    for scene in args.scenes:  # every scene checked before anything is written
        try:  # the scene, that it builds, and that the baselines can drive it
            Eq32Design(buildable_scene(scene))
        except ValueError as e:
            p.error(f"--scenes: {e}")
        key = scene_key(scene)  # the rows, plot and runs folder of a scene go by its key
        if key in keys:
            p.error(
                f"--scenes: {keys[key]!r} and {scene!r} have the same scene key {key!r} "
                "(the same scene, or scene files with the same stem): their rows, plot and "
                "runs folder would collide; give each scene once"
            )
        keys[key] = scene
    out, runs = Path(args.out), (None if args.baselines_only else Path(args.runs))
    if runs is not None and not runs.is_dir():  # a mistyped --runs would replace the
        # committed table with a baselines-only one
        p.error(
            f"--runs: no folder {str(runs)!r} (train agents first, see docs/agents.md, or pass "
            "--baselines-only to compare the Eq. 32 baselines alone)"
        )
    try:  # the output folder must take files, before any evaluation work
        out.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=out, prefix=".probe.")
        probe.close()
    except OSError as e:
        p.error(f"--out: cannot write to {str(out)!r}: {e}")
    setups = []
    for scene in args.scenes:  # every agent loaded and checked before any episode runs
        env = rolling_env.make(scene)
        try:
            setups.append((scene, env, controllers_for(scene, runs, env, args.model)))
        except (ValueError, OSError, KeyError) as e:
            p.error(f"--runs: {e}")
        if runs is not None and set(setups[-1][2]) <= set(BASELINES):  # no agent
            p.error(
                f"--runs: no trained agent for scene {scene!r} under "
                f"{str(runs / scene_key(scene))!r} (train one, leave the scene out of "
                "--scenes, or pass --baselines-only)"
            )
    rows, plots = [], []
    for scene, env, ctrls in setups:
        r, traj = evaluate_scene(scene, runs, args.episodes, env, ctrls)
        rows += r
        plots.append((scene, traj))
        for row in r:
            print(
                f"{row['scene']:20s} {row['controller']:16s} final|e|/tol "
                f"{row['final_abs_error_mean'] / row['tolerance']:8.2f}  reached "
                f"{row['reached_fraction']:.2f}  slip {row['slip_work_mean']:.3e} J",
                flush=True,
            )
    with staged():  # written only once every scene has been evaluated, and all or none
        marks = numerics_marks(rows)
        for scene, traj in plots:
            key = scene_key(scene)
            notes = {
                r["controller"]: r.get("trained_numerics", "") for r in rows if r["scene"] == key
            }
            plot_scene(scene, runs, traj, out, notes, marks)
        write_tables(rows, out, args.episodes, args.model)
    return 0


if __name__ == "__main__":
    sys.exit(main())
