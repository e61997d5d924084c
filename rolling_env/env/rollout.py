"""Roll out a controller in a scene and keep the trajectory (CSV + plot).

A controller is anything with SB3's ``predict(obs, state=None, episode_start=None,
deterministic=True) -> (action, state)``: a trained SB3 model (loaded through an installed
model loader, ``load_model``), the Eq. 32 baselines of ``rolling_env.env.baselines``, or the two
trivial ones here.
"""

from __future__ import annotations

import csv
import io
import os
from pathlib import Path

import numpy as np

from rolling_env.io import atomic_write, write_text

COLUMNS = (
    "step",
    "t",
    "target",
    "xstar",
    "vstar",
    "error",
    "N",
    "T",
    "omega_R",
    "v",
    "stick_fraction",
    "slip_work",
    "reward",
    "reward_track",
    "reward_wear",
    "saturated",
    "a_force",
    "a_roll",
    "a_creep",
)


class RandomController:
    """Uniform random actions from the env's action space (seeded)."""

    def __init__(self, action_space, seed=None):
        self.space = action_space
        self.space.seed(seed)

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return self.space.sample(), state


class ZeroController:
    """Always the zero action: mid force, no rolling, no creep."""

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        return np.zeros(3, np.float32), state


def rollout(env, controller, *, seed=0, target=None, max_steps=None) -> dict:
    """Run one episode; returns per-step arrays (keys ``COLUMNS``) and the episode's totals."""
    options = None if target is None else {"target": float(target)}
    obs, info = env.reset(seed=seed, options=options)
    rows = []
    state = None
    start = True
    dt = env.unwrapped.dt
    k = 0
    while True:
        action, state = controller.predict(
            obs, state=state, episode_start=np.array([start]), deterministic=True
        )
        action = np.asarray(action, dtype=np.float32).reshape(3)
        start = False
        obs, reward, terminated, truncated, info = env.step(action)
        k += 1
        rows.append(
            (
                k,
                k * dt,
                info["target"],
                info["xstar"],
                info["vstar"],
                info["error"],
                info["N"],
                info["T"],
                info["omega_R"],
                info["v"],
                info["stick_fraction"],
                info["slip_work"],
                reward,
                info["reward_track"],
                info["reward_wear"],
                float(info["saturated"]),
                *action.tolist(),
            )
        )
        if terminated or truncated or (max_steps is not None and k >= max_steps):
            break
    data = {c: np.array([r[i] for r in rows]) for i, c in enumerate(COLUMNS)}
    data["return"] = float(data["reward"].sum())
    data["final_error"] = float(data["error"][-1])
    data["total_slip_work"] = float(data["slip_work"].sum())
    return data


def write_csv(data: dict, path: str | os.PathLike) -> Path:
    """Write the per-step columns atomically (temp file + rename)."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(COLUMNS)
    for i in range(len(data["step"])):
        w.writerow([repr(float(data[c][i])) for c in COLUMNS])
    return write_text(path, buf.getvalue())


def plot(data: dict, path: str | os.PathLike, title: str = "") -> Path:
    """Runner against target, forces, and actions over the episode (PNG, written atomically)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    t = data["t"] * 1e3
    fig, ax = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    ax[0].plot(t, data["xstar"] * 1e9, label="runner x*")
    ax[0].plot(t, data["target"] * 1e9, "k--", label="target")
    ax[0].set_ylabel("displacement [nm]")
    ax[0].legend()
    ax[0].set_title(title)
    ax[1].plot(t, data["N"], label="N [N]")
    ax[1].plot(t, data["T"], label="T [N]")
    ax[1].set_ylabel("force [N]")
    ax[1].legend()
    for c in ("a_force", "a_roll", "a_creep"):
        ax[2].plot(t, data[c], label=c, lw=0.8)
    ax[2].set_ylabel("action")
    ax[2].set_xlabel("t [ms]")
    ax[2].legend(ncol=3)
    fig.tight_layout()
    try:
        atomic_write(path, lambda p: fig.savefig(p, dpi=100, format="png"))
    finally:
        plt.close(fig)
    return path


def controller_label(name: str) -> str:
    """A controller's part of output file names: its name, or for a model .zip its run
    folder and file stem (``runs/default/ppo_seed0/model.zip`` -> ``ppo_seed0-model``), so
    that the models of two runs of one scene folder never write the same files (runs of the
    same name under two scene keys whose scenes share a ``name``, e.g. ``runs/default/`` and
    ``runs/default-<digest8>/``, do: give them different ``--out`` folders)."""
    p = Path(name)
    if p.suffix != ".zip":
        return name
    run = p.resolve().parent.name
    return f"{run}-{p.stem}" if run else p.stem


MODEL_LOADERS = "rolling_drive.model_loaders"


def load_model(path, env, scene=None):
    """A trained model as a controller, through the loader an installed package registers
    under the entry-point group ``rolling_drive.model_loaders`` (``sb3``: agents.evaluate's
    ``load_checked_agent``, which refuses a model trained on another scene than ``scene``).
    The library imports no agent code of its own accord."""
    from importlib.metadata import entry_points

    found = {e.name: e for e in entry_points(group=MODEL_LOADERS)}
    if not found:
        raise ValueError(
            f"controller {str(path)!r} is a model .zip, but no model loader is installed "
            f"(entry-point group {MODEL_LOADERS!r}; installing rolling-drive, or re-running "
            "`pip install -e .` in a checkout, registers agents' SB3 loader)"
        )
    entry = found.get("sb3") or found[sorted(found)[0]]
    return entry.load()(path, env, scene)


def make_controller(name: str, env, seed=0, scene=None):
    """``random``, ``zero``, ``eq32`` (or ``eq32-open-loop``, its name in ``agents.evaluate``'s
    tables), ``eq32-feedback`` or a path to an SB3 model .zip
    (trained by ``agents.train``; its VecNormalize statistics are applied if present).  A
    model whose run folder's config.yml says it was trained on another scene than ``scene``
    (as given: name or path; default the env's scene, compared by content) is refused."""
    if name == "random":
        return RandomController(env.action_space, seed)
    if name == "zero":
        return ZeroController()
    if name in ("eq32", "eq32-open-loop", "eq32-feedback"):
        from rolling_env.env import baselines

        cls = baselines.Eq32Feedback if name == "eq32-feedback" else baselines.Eq32OpenLoop
        return cls.from_env(env)
    if name.endswith(".zip") and Path(name).exists():
        return load_model(name, env, scene)
    raise ValueError(
        f"controller must be random, zero, eq32 (or eq32-open-loop), "
        f"eq32-feedback or an existing model .zip, got {name!r}"
    )
