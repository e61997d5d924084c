"""Shared pieces of training and evaluation: hyper-parameters, vector envs, atomic saving."""

from __future__ import annotations

import os
import re
from pathlib import Path

from rolling_env.env.scenes import (  # noqa: F401  (re-exported: run folders record them)
    fields_digest,
    read_yaml,
    scene_digest,
    scene_fields,
    scene_key,
)
from rolling_env.io import atomic_write  # noqa: F401  (re-exported)
from rolling_env.paths import HYPERPARAM_DIR as CONF_DIR

EVAL_SEED = 20261122  # held out: training uses seeds < 1e6, evaluation envs seed + 10000
MACHINE = "2-core x86_64 CPU, no GPU"  # where the committed runs were trained


class UsageError(ValueError):
    """A bad scene, hyper-parameter or argument, found before training starts."""


ALGOS = ("ppo", "sac", "td3")


def load_hyperparams(algo: str, scene: str, conf: str | os.PathLike | None = None) -> dict:
    """The scene's entry of ``configs/hyperparams/<algo>.yml`` (RL Zoo format); falls back to
    the env id's entry (``RollingDrive-v0``) with ``env_kwargs.scene`` set to ``scene``.
    The entry is returned as written; ``check_hyperparams`` validates it."""
    if algo not in ALGOS:
        raise ValueError(f"algo must be one of {ALGOS}, got {algo!r}")
    path = Path(conf) if conf else CONF_DIR / f"{algo}.yml"
    table = read_yaml(path, "hyper-parameter file")
    if not isinstance(table, dict) or not (scene in table or "RollingDrive-v0" in table):
        raise ValueError(
            f"{path}: needs an entry for scene {scene!r} or for RollingDrive-v0 (RL Zoo format)"
        )
    key = scene if scene in table else "RollingDrive-v0"
    if not isinstance(table[key], dict):
        raise ValueError(
            f"{path}: the entry {key!r} must be a mapping of hyper-parameters, got {table[key]!r}"
        )
    hp = dict(table[key])
    if key != scene:
        env_kwargs = hp.get("env_kwargs") or {}
        if not isinstance(env_kwargs, dict):
            raise ValueError(f"hyper-parameter 'env_kwargs' must be a mapping, got {env_kwargs!r}")
        hp["env_kwargs"] = dict(env_kwargs, scene=scene)
    return hp


def one_line(e: BaseException, limit: int = 200) -> str:
    """``ExcType: message`` of a library's exception for a one-line error: the message's
    first sentence, whitespace collapsed, at most ``limit`` characters."""
    msg = " ".join(str(e).split())
    msg = msg.split(". ")[0]
    if len(msg) > limit:
        msg = msg[: limit - 3] + "..."
    return f"{type(e).__name__}: {msg}" if msg else type(e).__name__


def run_config(run: str | os.PathLike) -> dict | None:
    """A run folder's config.yml (written by agents.train) as a mapping, None where the run
    has none; a ValueError naming the file where it is damaged: not YAML, not UTF-8, not a
    mapping, or with ``env_kwargs`` / ``scene_fields`` that are not mappings and ``algo``,
    ``scene``, ``scene_key``, ``scene_digest`` that are not strings."""
    path = Path(run) / "config.yml"
    if not path.exists():
        return None
    cfg = read_yaml(path, "run config")
    if cfg is None:
        cfg = {}
    if not isinstance(cfg, dict):
        raise ValueError(
            f"run config {str(path)!r} must hold a mapping (written by "
            f"agents.train), got a {type(cfg).__name__}"
        )
    for key, kind in (
        ("env_kwargs", dict),
        ("scene_fields", dict),
        ("algo", str),
        ("scene", str),
        ("scene_key", str),
        ("scene_digest", str),
    ):
        if cfg.get(key) is not None and not isinstance(cfg[key], kind):
            raise ValueError(
                f"run config {str(path)!r}: {key!r} must be a "
                f"{'mapping' if kind is dict else 'string'}, got {cfg[key]!r}"
            )
    return cfg


def make_vec_env(
    scene,
    n_envs: int,
    seed: int,
    env_kwargs: dict | None = None,
    kind: str = "batched",
    num_threads=None,
):
    """The training vector env, wrapped in ``VecMonitor``.  ``kind="batched"``: the natively
    batched ``rolling_env.env.sb3_vec.RollingDriveVecEnv`` (one compiled call steps all envs;
    ``num_threads`` as there: None picks the serial or threaded kernel step by step from
    measured step times).  ``kind="dummy"``: SB3's ``DummyVecEnv`` of single envs.  Both give
    the same transitions; which steps faster depends on the host (``rolling-drive bench``,
    results/benchmarks.md: the batched env is 2-6x faster on an idle host), which is why
    ``agents.train`` measures both at start.  ``SubprocVecEnv`` is slower still on 2 cores
    (IPC dominates).  Env i is seeded ``seed + i`` like SB3's make_vec_env."""
    from stable_baselines3.common.vec_env import DummyVecEnv, VecMonitor

    kw = dict(env_kwargs or {})
    kw.pop("scene", None)
    if kind == "batched":
        from rolling_env.env.sb3_vec import RollingDriveVecEnv

        venv = RollingDriveVecEnv(n_envs, scene=scene, num_threads=num_threads, **kw)
    elif kind == "dummy":
        import rolling_env

        envs = [rolling_env.make(scene, **kw) for _ in range(n_envs)]
        venv = DummyVecEnv([lambda e=e: e for e in envs])
    else:
        raise ValueError(f"kind must be 'batched' or 'dummy', got {kind!r}")
    venv = VecMonitor(venv)
    venv.seed(seed)
    return venv


SAVED_AT = "rolling_drive_saved_at_timesteps"  # attribute of saved VecNormalize statistics


def save_model(model, vecnorm, folder: str | os.PathLike, name: str = "model") -> Path:
    """Save ``<name>.zip`` and, beside it, ``<name>_vecnormalize.pkl`` atomically.  The
    statistics carry the model's step count (``SAVED_AT``): two files cannot be replaced in
    one atomic step, so a process killed between the two writes leaves a pair that
    ``loading.load_agent`` recognises as mismatched instead of silently using it."""
    folder = Path(folder)
    if vecnorm is not None:
        setattr(vecnorm, SAVED_AT, int(model.num_timesteps))
        atomic_write(folder / f"{name}_vecnormalize.pkl", vecnorm.save)
    return atomic_write(folder / f"{name}.zip", model.save)


# ----------------------------------------------------------------- scenes of runs
#: the scene keys that set how finely the env integrates the physics, not the physics or
#: the task (``n_sub``: the sub-steps per tick they resolve to, ``Scene.n_sub``).  A run whose
#: recorded scene differs from the evaluated one only in these is evaluated and marked
#: (``numerics_note``); a difference in any other key refuses it.
NUMERICS_KEYS = ("sub_steps", "resolution", "accuracy", "grid_levels", "n_sub")

#: the reward's weights: they shape what an agent learns from, not what the comparison scores
#: (final error and slip work), so a run trained with other weights (``env_kwargs``, e.g.
#: ``w_final``) is evaluated on the plain scene and marked like one trained on other numerics
REWARD_KEYS = ("w_track", "w_wear", "w_final")

#: numerics keys added after runs were recorded, with the value in effect before each existed
#: (where that differs from the key's default): one fixed grid before the level grid
BEFORE_KEY = {"grid_levels": 0}


def completed_fields(fields: dict) -> dict:
    """A run's recorded ``scene_fields`` with what a run recorded before a key existed filled
    in: a Scene field with a default (``accuracy``) takes its default, as a scene file that
    leaves it out does, or the value in effect before it existed (``BEFORE_KEY``:
    ``grid_levels`` 0), and ``n_sub`` the recorded ``sub_steps`` where that is a number."""
    import dataclasses

    from rolling_env.env.scenes import Scene

    out = dict(fields)
    for f in dataclasses.fields(Scene):
        if (
            f.name not in out
            and f.name not in ("name", "description")
            and f.default is not dataclasses.MISSING
        ):
            v = BEFORE_KEY.get(f.name, f.default)
            out[f.name] = list(v) if isinstance(v, tuple) else v
    sub = out.get("sub_steps")
    if "n_sub" not in out and isinstance(sub, int) and not isinstance(sub, bool):
        out["n_sub"] = sub
    return out


def _sub_steps_text(fields: dict) -> str:
    sub, n = fields.get("sub_steps", "-"), fields.get("n_sub")
    return f"auto: {n}" if sub == "auto" and n is not None else f"{sub}"


def numerics_note(trained: dict, now: dict) -> str:
    """What differs between two ``scene_fields`` in ``NUMERICS_KEYS`` and ``REWARD_KEYS``, for
    the tables: ``sub_steps 8 (now auto: 46), resolution 16 (now 32)``; "" where nothing
    does."""
    parts = []
    if any(trained.get(k) != now.get(k) for k in ("sub_steps", "n_sub")):
        parts.append(f"sub_steps {_sub_steps_text(trained)} (now {_sub_steps_text(now)})")
    for k in ("resolution", "accuracy", "grid_levels") + REWARD_KEYS:
        if trained.get(k) != now.get(k):
            parts.append(
                f"{k} {trained.get(k, '-'):g} (now {now.get(k, '-'):g})"
                if isinstance(trained.get(k), (int, float)) and isinstance(now.get(k), (int, float))
                else f"{k} {trained.get(k, '-')!r} (now {now.get(k, '-')!r})"
            )
    return ", ".join(parts)


def differing_fields(a: dict, b: dict) -> str:
    """``key a vs b`` for the fields where two ``scene_fields`` differ (for messages), the
    physics and task keys before the numerics (``NUMERICS_KEYS``)."""
    keys = sorted(set(a) | set(b), key=lambda k: (k in NUMERICS_KEYS, k))  # physics first
    diff = [f"{k} {a.get(k, '-')!r} vs {b.get(k, '-')!r}" for k in keys if a.get(k) != b.get(k)]
    return ", ".join(diff[:6]) + (f" (+{len(diff) - 6} more)" if len(diff) > 6 else "")


def buildable_scene(scene):
    """The checked Scene, also checked to build (``load_scene`` bounds each key, but e.g. a
    fine resolution over a long stroke needs more spring cells than the model allows): a
    ValueError naming the scene keys where it does not."""

    from rolling_env.env.drive_env import build_drive
    from rolling_env.env.scenes import load_scene

    sc = load_scene(scene)
    name = str(scene) if isinstance(scene, (str, os.PathLike)) else sc.name
    try:
        build_drive(sc)
    except ValueError as e:
        m = re.search(r"would need (\d+) cells", str(e))
        if m is None:
            raise ValueError(f"scene {name!r} cannot be built: {e}") from None
        raise ValueError(
            f"scene {name!r}: scene keys 'resolution' = {sc.resolution:g} (cells "
            f"per contact radius) and 'stroke_roll' = {sc.stroke_roll:g} m need "
            f"{m.group(1)} spring cells (at most 2e7): lower resolution or "
            "stroke_roll"
        ) from None
    return sc
