"""Evaluate every controller on the same held-out targets and seeds, per scene.

    python -m agents.evaluate --scenes default resonant ... --runs runs/ --episodes 20

Controllers: the two Eq. 32 baselines and every trained agent under ``<runs>/<scene>/*/``
(its best model from EvalCallback if present, else the final model, with the VecNormalize
statistics saved beside it).  Writes ``results/comparison.md`` and ``results/comparison.csv``
(atomically) and plots under ``results/plots/``: learning curves per scene and one trajectory
per controller on the same target.
"""
from __future__ import annotations

import argparse
import csv
import io
import json
import sys
from pathlib import Path

import numpy as np

import rolling_env
from rolling_env.rollout import rollout

from .baselines import Eq32Feedback, Eq32OpenLoop
from .common import atomic_write

EVAL_SEED = 20261122  # held out: training uses seeds < 1e6, evaluation envs seed + 10000


class NormalizedAgent:
    """A trained SB3 model with its saved VecNormalize observation statistics applied."""

    def __init__(self, model, vecnorm=None):
        self.model = model
        self.vecnorm = vecnorm

    def predict(self, obs, state=None, episode_start=None, deterministic=True):
        if self.vecnorm is not None:
            obs = self.vecnorm.normalize_obs(np.asarray(obs))
        return self.model.predict(obs, state=state, episode_start=episode_start,
                                  deterministic=deterministic)


def load_agent(path, env=None) -> NormalizedAgent:
    """Load ``<name>.zip`` and ``<name>_vecnormalize.pkl`` (if beside it)."""
    import stable_baselines3 as sb3
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    path = Path(path)
    meta = path.parent / "config.yml"
    algo = "ppo"
    if meta.exists():
        import yaml
        algo = yaml.safe_load(meta.read_text()).get("algo", "ppo")
    cls = {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]
    model = cls.load(path, device="cpu")
    stats = path.with_name(path.stem.replace("best_model", "model") + "_vecnormalize.pkl")
    if path.stem == "best_model":
        stats = path.with_name("model_vecnormalize.pkl")
        if not stats.exists():
            stats = path.with_name("checkpoint_vecnormalize.pkl")
    vecnorm = None
    if stats.exists():
        dummy = DummyVecEnv([lambda: rolling_env.make(env.unwrapped.scene if env is not None
                                                      else "default")])
        vecnorm = VecNormalize.load(str(stats), dummy)
        vecnorm.training = False
        vecnorm.norm_reward = False
    return NormalizedAgent(model, vecnorm)


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
    return {"final_abs_error": float(e[-1]), "rms_error": float(np.sqrt(np.mean(e ** 2))),
            "settle_time": t_settle, "slip_work": float(data["total_slip_work"]),
            "return": float(data["return"])}


def controllers_for(scene: str, runs: Path, env) -> dict:
    ctrls = {"eq32-open-loop": Eq32OpenLoop.from_env(env),
             "eq32-feedback": Eq32Feedback.from_env(env)}
    for run in sorted((runs / scene).glob("*")):
        model = run / "best_model.zip"
        if not model.exists():
            model = run / "model.zip"
        if model.exists():
            ctrls[run.name] = load_agent(model, env)
    return ctrls


def evaluate_scene(scene: str, runs: Path, episodes: int) -> tuple[list[dict], dict]:
    env = rolling_env.make(scene)
    tol = env.unwrapped.scene.tolerance
    targets = held_out_targets(scene, episodes)
    rows, trajectories = [], {}
    for name, ctrl in controllers_for(scene, runs, env).items():
        per = []
        for i, target in enumerate(targets):
            data = rollout(env, ctrl, seed=EVAL_SEED + i, target=target)
            per.append(episode_metrics(data, tol))
            if i == 0:
                trajectories[name] = data
        row = {"scene": scene, "controller": name, "episodes": len(per)}
        for key in ("final_abs_error", "rms_error", "slip_work", "return"):
            vals = np.array([p[key] for p in per])
            row[f"{key}_mean"] = float(vals.mean())
            row[f"{key}_std"] = float(vals.std())
        settle = np.array([p["settle_time"] for p in per])
        row["reached_fraction"] = float(np.mean(np.isfinite(settle)))
        row["settle_time_mean"] = (float(np.nanmean(settle)) if np.any(np.isfinite(settle))
                                   else float("nan"))
        row["tolerance"] = tol
        row.update(_budget(runs / scene / name))
        rows.append(row)
    env.close()
    return rows, trajectories


def _budget(run: Path) -> dict:
    meta = run / "meta.json"
    if not meta.exists():
        return {"train_env_steps": 0, "train_wall_seconds": 0.0}
    m = json.loads(meta.read_text())
    return {"train_env_steps": m["env_steps"], "train_wall_seconds": round(m["wall_seconds"], 1)}


COLS = ["scene", "controller", "episodes", "tolerance", "final_abs_error_mean",
        "final_abs_error_std", "rms_error_mean", "rms_error_std", "reached_fraction",
        "settle_time_mean", "slip_work_mean", "slip_work_std", "return_mean", "train_env_steps",
        "train_wall_seconds"]


def write_tables(rows: list[dict], out: Path) -> None:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLS, extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    atomic_write(out / "comparison.csv", lambda p: Path(p).write_text(buf.getvalue()))
    lines = ["# Controllers compared on held-out targets", "",
             "Generated by `python -m agents.evaluate` (see README).  Per scene: the same "
             f"targets and seeds (base seed {EVAL_SEED}) for every controller.  Errors in "
             "units of the scene's tolerance; slip work in nJ; settle = time after which "
             "|error| stays within the tolerance (mean over the episodes that settle).", "",
             "| scene | controller | final abs error / tol (mean ± std) | RMS error / tol | "
             "reached | settle [ms] | slip work [nJ] | training (env steps, wall s) |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        tol = r["tolerance"]
        st = r["settle_time_mean"]
        settle = "never" if not np.isfinite(st) else f"{st * 1e3:.2f}"
        budget = (f"{r['train_env_steps']:,}, {r['train_wall_seconds']:.0f}"
                  if r["train_env_steps"] else "-")
        lines.append(
            f"| {r['scene']} | {r['controller']} | {r['final_abs_error_mean'] / tol:.2f} ± "
            f"{r['final_abs_error_std'] / tol:.2f} | {r['rms_error_mean'] / tol:.1f} | "
            f"{100 * r['reached_fraction']:.0f}% | {settle} | {r['slip_work_mean'] * 1e9:.3g} | "
            f"{budget} |")
    atomic_write(out / "comparison.md", lambda p: Path(p).write_text("\n".join(lines) + "\n"))


def plot_scene(scene: str, runs: Path, trajectories: dict, out: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for name, data in trajectories.items():
        ax[0].plot(data["t"] * 1e3, data["xstar"] * 1e9, label=name)
    first = next(iter(trajectories.values()))
    ax[0].plot(first["t"] * 1e3, first["target"] * 1e9, "k--", label="target")
    ax[0].set_xlabel("t [ms]")
    ax[0].set_ylabel("runner x* [nm]")
    ax[0].set_title(f"{scene}: one held-out target")
    ax[0].legend(fontsize=7)
    for run in sorted((runs / scene).glob("*")):
        ev = run / "evaluations.npz"
        if ev.exists():
            d = np.load(ev)
            ax[1].plot(d["timesteps"], d["results"].mean(axis=1), label=run.name)
    ax[1].set_xlabel("env steps")
    ax[1].set_ylabel("mean eval return")
    ax[1].set_title("learning curves (EvalCallback)")
    if ax[1].lines:
        ax[1].legend(fontsize=7)
    fig.tight_layout()
    atomic_write(out / "plots" / f"{scene}.png", lambda p: fig.savefig(p, dpi=90, format="png"))
    plt.close(fig)


def main(argv=None):
    p = argparse.ArgumentParser(prog="python -m agents.evaluate", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", nargs="+", default=rolling_env.list_scenes())
    p.add_argument("--runs", default="runs")
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--out", default="results")
    args = p.parse_args(argv)
    out, runs = Path(args.out), Path(args.runs)
    rows = []
    for scene in args.scenes:
        r, traj = evaluate_scene(scene, runs, args.episodes)
        rows += r
        plot_scene(scene, runs, traj, out)
        for row in r:
            print(f"{scene:20s} {row['controller']:18s} final|e|/tol {row['final_abs_error_mean'] / row['tolerance']:8.2f}"
                  f"  reached {row['reached_fraction']:.2f}  slip {row['slip_work_mean']:.3e} J")
    write_tables(rows, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
