"""Shared pieces of training and evaluation: hyper-parameters, vector envs, atomic saving."""
from __future__ import annotations

import ast
import os
from pathlib import Path

import yaml

from rolling_env.io import atomic_write  # noqa: F401  (re-exported)

REPO = Path(__file__).resolve().parent.parent
CONF_DIR = REPO / "configs" / "hyperparams"
ALGOS = ("ppo", "sac", "td3")


def load_hyperparams(algo: str, scene: str, conf: str | os.PathLike | None = None) -> dict:
    """The scene's entry of ``configs/hyperparams/<algo>.yml`` (RL Zoo format); falls back to
    the env id's entry (``RollingDrive-v0``) with ``env_kwargs.scene`` set to ``scene``."""
    if algo not in ALGOS:
        raise ValueError(f"algo must be one of {ALGOS}, got {algo!r}")
    path = Path(conf) if conf else CONF_DIR / f"{algo}.yml"
    with open(path) as f:
        table = yaml.safe_load(f)
    if not isinstance(table, dict) or not (scene in table or "RollingDrive-v0" in table):
        raise ValueError(f"{path}: needs an entry for scene {scene!r} or for RollingDrive-v0 "
                         "(RL Zoo format)")
    if scene in table:
        hp = dict(table[scene])
    else:
        hp = dict(table["RollingDrive-v0"])
        hp["env_kwargs"] = dict(hp.get("env_kwargs", {}), scene=scene)
    return hp


def parse_kwargs(text) -> dict:
    """RL Zoo writes policy_kwargs / normalize as Python literals in strings: "dict(a=1)"."""
    if text is None or isinstance(text, dict):
        return dict(text or {})
    if isinstance(text, bool):
        return {} if text else None
    node = ast.parse(str(text), mode="eval").body
    if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "dict":
        return {kw.arg: ast.literal_eval(kw.value) if not isinstance(kw.value, ast.Call)
                else parse_kwargs(ast.unparse(kw.value)) for kw in node.keywords}
    return ast.literal_eval(node)


def make_vec_env(scene, n_envs: int, seed: int, env_kwargs: dict | None = None):
    """The training vector env, chosen here and only here: the natively batched
    ``rolling_env.vector.RollingDriveVecEnv`` (one compiled call steps all envs), wrapped in
    ``VecMonitor``.  It is faster than SB3's ``DummyVecEnv`` of single envs at every batch size
    (2x at 1 env, about 6x at 8: ``rolling-drive bench``, results/benchmarks.md), and
    ``SubprocVecEnv`` is slower still on 2 cores (IPC dominates).  Env i is seeded ``seed + i``
    like SB3's make_vec_env."""
    from stable_baselines3.common.vec_env import VecMonitor

    from rolling_env.vector import RollingDriveVecEnv

    kw = dict(env_kwargs or {})
    kw.pop("scene", None)
    venv = VecMonitor(RollingDriveVecEnv(n_envs, scene=scene, **kw))
    venv.seed(seed)
    return venv


SAVED_AT = "rolling_drive_saved_at_timesteps"  # attribute of saved VecNormalize statistics


def save_model(model, vecnorm, folder: str | os.PathLike, name: str = "model") -> Path:
    """Save ``<name>.zip`` and, beside it, ``<name>_vecnormalize.pkl`` atomically.  The
    statistics carry the model's step count (``SAVED_AT``): two files cannot be replaced in
    one atomic step, so a process killed between the two writes leaves a pair that
    ``evaluate.load_agent`` recognises as mismatched instead of silently using it."""
    folder = Path(folder)
    if vecnorm is not None:
        setattr(vecnorm, SAVED_AT, int(model.num_timesteps))
        atomic_write(folder / f"{name}_vecnormalize.pkl", vecnorm.save)
    return atomic_write(folder / f"{name}.zip", model.save)
