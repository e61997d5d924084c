"""Loading trained agents and checking them against the scene they are evaluated on.

A run folder's model (``agent_files``: final, best or an interrupted run's checkpoint), its
VecNormalize statistics and its recorded scene (``check_run_scene``: refused where the physics
or the task differ, marked where only the numerics do); a damaged file is one line naming it.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import numpy as np

import rolling_env

from .common import SAVED_AT, one_line, run_config, scene_key


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
    from .residual import ResidualAgent

    path = Path(path)
    cfg = run_config(path.parent)  # None without one; a damaged one is a ValueError
    model = _load_model(path, cfg)
    residual = _residual_of(cfg, path)
    _check_observation_width(model, path, residual)
    period = _period_of(cfg, path)
    _check_action_width(model, path, period)
    agent = NormalizedAgent(model, _load_statistics(path, model, cfg, env, residual))
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


def _load_model(path: Path, cfg: dict | None):
    """The SB3 model of ``path``, its algorithm read from the zip and checked against the
    run's config.yml ``cfg`` (None: none to check against)."""
    import stable_baselines3 as sb3

    algo = model_algo(path)
    if cfg is not None and cfg.get("algo", algo) != algo:
        raise ValueError(
            f"{path.name} was saved by {algo.upper()} but {path.parent / 'config.yml'} says "
            f"algo {cfg.get('algo')!r}: the model does not belong to this run"
        )
    cls = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]
    try:
        return cls.load(path, device="cpu")
    except Exception as e:  # noqa: BLE001  (a damaged policy.pth: torch's RuntimeError, ...)
        raise _load_error(path, e) from None


def _check_observation_width(model, path: Path, residual) -> None:
    """Refuse a residual model (told by its observation width) whose run's config.yml, which
    names its baseline, is not beside it (``residual`` None)."""
    from rolling_env.env.drive_env import OBS_NAMES

    from .residual import N_BASE

    width = getattr(model.observation_space, "shape", (0,))[0]
    if residual is None and width == len(OBS_NAMES) + N_BASE:
        raise ValueError(
            f"{path} takes {width} observations: it is a residual agent (the env's "
            f"{len(OBS_NAMES)} and its baseline's action), and the config.yml of "
            "its run, which names the baseline, is not beside it"
        )


def _check_action_width(model, path: Path, period: bool) -> None:
    """Refuse a period-level model (told by its action width) whose run's config.yml, which
    says so, is not beside it (``period`` False)."""
    from .period import N_ACTION as N_PERIOD_ACTION

    n_act = getattr(model.action_space, "shape", (0,))[0]
    if not period and n_act == N_PERIOD_ACTION:
        raise ValueError(
            f"{path} acts with {n_act} numbers: it is a period-level agent (an Eq. 32 "
            "working point per period), and the config.yml of its run, which says so, is "
            "not beside it"
        )


def _load_statistics(path: Path, model, cfg: dict | None, env, residual):
    """The frozen VecNormalize statistics saved beside the model (None without them), checked
    to be saved with it; their absence refused where the run's config.yml says it normalised
    observations, and warned about where there is no config.yml."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from .hyperparams import parse_kwargs
    from .residual import ResidualVecEnv

    stats = path.with_name(path.stem + "_vecnormalize.pkl")
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
        return vecnorm
    if cfg is not None:
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
    return None


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
    from rolling_env.env.scenes import load_scene

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
    from rolling_env.env.scenes import Scene

    from .common import REWARD_KEYS

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
    return _numerics_difference(run, cfg, scene, name)


def _numerics_difference(run: Path, cfg: dict, scene, name: str) -> str:
    """What differs between the scene content recorded in a run's config.yml ``cfg`` and
    ``scene``'s now ("" where nothing does; a warning printed where something does); a
    ValueError where anything but the numerics and reward weights differs, or where the
    recorded fields do not reproduce the recorded digest and the digests differ."""
    from .common import (
        NUMERICS_KEYS,
        REWARD_KEYS,
        completed_fields,
        differing_fields,
        fields_digest,
        numerics_note,
        scene_fields,
    )

    digest = cfg["scene_digest"]
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
