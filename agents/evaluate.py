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
import sys
import tempfile
from pathlib import Path

import numpy as np

import rolling_env
from rolling_env.cli.main import positive_int
from rolling_env.env.rollout import rollout
from rolling_env.io import staged

from .baselines import Eq32Design, Eq32Feedback, Eq32OpenLoop
from .common import (
    EVAL_SEED,
    buildable_scene,
    scene_key,
)
from .loading import (
    MODELS,
    MismatchedStatistics,
    agent_files,
    check_run_scene,
    load_agent,
    scene_runs,
)
from .report import _budget, _config_key, learning_curve, plot_scene, read_goal_log, write_tables
from .verdicts import (
    BASELINES,
    numerics_marks,
)

#: --episodes at most: an episode of a shipped scene (512 ticks) takes about 0.25 s per
#: controller on the 2-core machine, averaged over the shipped scenes (from heavy_inf_friction's
#: 8 sub-steps per tick to light_stiff's 75), so 1e5 episodes are about 7 hours per controller
#: and scene (1e9 built arrays until the process was killed for memory)
EPISODES_MAX = 10**5


def held_out_targets(scene, n: int) -> list[float]:
    """n targets drawn from the scene's range with a fixed seed (the same for every controller)."""
    sc = rolling_env.env.scenes.load_scene(scene)
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


def _parser() -> argparse.ArgumentParser:
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
    return p


def _check_scenes(p, scenes) -> None:
    """Every scene builds, the baselines can drive it, and no two share a scene key; else a
    usage error."""
    keys = {}
    for scene in scenes:  # every scene checked before anything is written
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


def _check_folders(p, out: Path, runs: Path | None) -> None:
    """``runs`` (None: baselines only) exists and ``out`` takes files; else a usage error."""
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


def _setups(p, scenes, runs: Path | None, model: str) -> list:
    """(scene, env, controllers) per scene, every agent loaded and checked; a usage error
    where one cannot be, or where a scene has no agent (unless ``runs`` is None)."""
    setups = []
    for scene in scenes:  # every agent loaded and checked before any episode runs
        env = rolling_env.make(scene)
        try:
            setups.append((scene, env, controllers_for(scene, runs, env, model)))
        except (ValueError, OSError, KeyError) as e:
            p.error(f"--runs: {e}")
        if runs is not None and set(setups[-1][2]) <= set(BASELINES):  # no agent
            p.error(
                f"--runs: no trained agent for scene {scene!r} under "
                f"{str(runs / scene_key(scene))!r} (train one, leave the scene out of "
                "--scenes, or pass --baselines-only)"
            )
    return setups


def main(argv=None):
    p = _parser()
    args = p.parse_args(argv)
    _check_scenes(p, args.scenes)
    out, runs = Path(args.out), (None if args.baselines_only else Path(args.runs))
    _check_folders(p, out, runs)
    setups = _setups(p, args.scenes, runs, args.model)
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
