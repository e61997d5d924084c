"""The comparison's tables and plots: per-run rows, the seed summary, the goal table, the
rliable statistics, the episodes CSV and the per-scene figure (learning curves and one
trajectory per controller on the same target).
"""

from __future__ import annotations

import csv
import io
import json
import sys
from pathlib import Path

import numpy as np

import rolling_env

from .common import (
    EVAL_SEED,
    MACHINE,
    atomic_write,
    one_line,
    run_config,
    scene_key,
)
from .loading import _load_error, scene_runs
from .verdicts import (
    BASELINES,
    goal_verdicts,
    marked,
    numerics_marks,
    one_configuration,
    seed_groups,
)


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
    from .train_callbacks import GOAL_LOG

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
    """comparison.csv and comparison.md under ``out`` (with the statistics over seeds and
    targets, their plot and the episodes CSV where there are agents with per-episode data)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=COLS, extrasaction="ignore")
    w.writeheader()
    w.writerows(rows)
    atomic_write(out / "comparison.csv", lambda p: Path(p).write_text(buf.getvalue()))
    marks = numerics_marks(rows)
    note_of = {(r["scene"], r["controller"]): r.get("trained_numerics") or "" for r in rows}
    lines = _table_intro(rows, episodes, model, bool(marks))
    lines += [
        _table_row(r, marked(r["controller"], note_of[(r["scene"], r["controller"])], marks))
        for r in rows
    ]
    if marks:
        lines += [""] + [
            f"* [{k}] trained on other numerics or reward weights: {note}"
            for note, k in marks.items()
        ]
    lines += _goal_section(rows, note_of, marks)
    lines += _seed_section(rows, note_of, marks)
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


def _table_intro(rows: list[dict], episodes: int | None, model: str, marked_any: bool) -> list:
    """The page's title, what the table shows, and the head of the per-controller table."""
    n = episodes or (rows[0]["episodes"] if rows else 0)
    lengths = sorted(
        {(r.get("episode_steps"), r.get("episode_seconds")) for r in rows if r.get("episode_steps")}
    )
    length = (
        "; ".join(f"{k} ticks = {t * 1e3:.3g} ms" for k, t in lengths)
        or "the scene's episode_steps"
    )
    return [
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
            if marked_any
            else ""
        ),
        "",
        "| scene | controller | model | final abs error / tol (mean ± std) | RMS error / "
        "tol | reached | settle [ms] | slip work [nJ] (mean ± std) | training (env steps, "
        "wall s) |",
        "|---|---|---|---|---|---|---|---|---|",
    ]


def _table_row(r: dict, name: str) -> str:
    """One controller's row of the table (``name``: the controller with its mark)."""
    tol = r["tolerance"]
    budget = (
        f"{r['train_env_steps']:,}, {r['train_wall_seconds']:.0f}" if r["train_env_steps"] else "-"
    )
    return (
        f"| {r['scene']} | {name} | {r.get('model_file', '-')} | "
        f"{r['final_abs_error_mean'] / tol:.2f} ± "
        f"{r['final_abs_error_std'] / tol:.2f} | {r['rms_error_mean'] / tol:.1f} | "
        f"{100 * r['reached_fraction']:.0f}% | {_fmt_settle(r['settle_time_mean'])} | "
        f"{r['slip_work_mean'] * 1e9:.3g} ± {r['slip_work_std'] * 1e9:.2g} | {budget} |"
    )


def _goal_section(rows: list[dict], note_of: dict, marks: dict) -> list:
    """Each agent against its scene's best baseline (``goal_verdicts``); none without agents."""
    verdicts = goal_verdicts(rows)
    if not verdicts:
        return []
    lines = [
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
    return lines


def _seed_section(rows: list[dict], note_of: dict, marks: dict) -> list:
    """Runs of one configuration summed up over their seeds (``seed_summary``)."""
    summary = seed_summary(rows)
    if not summary:
        return []
    lines = [
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
    return lines


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

    tol = rolling_env.env.scenes.load_scene(scene).tolerance
    fig, ax = plt.subplots(1, 3, figsize=(16, 4.2))
    colors = {name: f"C{i % 10}" for i, name in enumerate(trajectories)}  # one per controller,
    # the same in every panel
    _plot_trajectories(ax[0], ax[1], scene, trajectories, tol, labels, colors)
    _plot_learning_curves(ax[2], scene_runs(scene, runs), labels, colors)
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


def _plot_trajectories(ax_x, ax_e, scene, trajectories, tol, labels, colors) -> None:
    """The runner against the target (``ax_x``) and |error| / tolerance (``ax_e``, log) of
    every controller on held-out target 0; baselines dashed."""
    for name, data in trajectories.items():
        ls = "--" if name in BASELINES else "-"
        label = labels.get(name, name)
        ax_x.plot(data["t"] * 1e3, data["xstar"] * 1e9, ls, label=label, color=colors[name])
        ax_e.semilogy(
            data["t"] * 1e3,
            np.maximum(np.abs(data["error"]) / tol, 1e-3),
            ls,
            label=label,
            color=colors[name],
        )
    first = next(iter(trajectories.values()))
    ax_x.plot(first["t"] * 1e3, first["target"] * 1e9, "k:", label="target")
    ax_x.set(
        xlabel="t [ms]",
        ylabel="runner x* [nm]",
        title=f"{scene}: held-out target {first['target'][0] * 1e9:.0f} nm",
    )
    ax_x.legend(fontsize=7)
    ax_e.axhline(1.0, color="k", lw=0.8)
    ax_e.set(
        xlabel="t [ms]",
        ylabel="|error| / tolerance",
        ylim=(1e-2, None),
        title="tracking error (line: tolerance)",
    )


def _plot_learning_curves(ax, runs, labels, colors) -> None:
    """EvalCallback's learning curve of each run (a run without a model in grey), or a note
    where there is none."""
    for run in runs:
        curve = learning_curve(run)
        if curve is not None:
            steps, mean, std = curve
            color = colors.get(run.name, "0.5")  # grey: a run without a model
            ax.plot(steps, mean, label=labels.get(run.name, run.name), color=color)
            ax.fill_between(steps, mean - std, mean + std, alpha=0.2, color=color)
    ax.set(
        xlabel="env steps",
        ylabel="eval return (mean ± std over episodes)",
        title="learning curves (EvalCallback)",
    )
    if ax.lines:
        ax.legend(fontsize=7)
    else:  # --baselines-only, or runs without an EvalCallback log: say so, not a blank panel
        ax.text(
            0.5,
            0.5,
            "no learning curves\n(baselines only, or no evaluations.npz)",
            ha="center",
            va="center",
            transform=ax.transAxes,
            fontsize=9,
        )
