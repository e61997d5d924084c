"""A sweep's results: one row per trial, the summary table, and the best search trial's
entry written into the sweep's hyper-parameter file."""

from __future__ import annotations

import math
from pathlib import Path

import yaml

from .common import atomic_write, scene_key
from .sweep_file import METRIC, TIME_ATTR, grid_trials


def _plain(d: dict) -> dict:
    """Sampled values as plain Python (numpy scalars would not dump as YAML)."""
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in d.items()}


def _rows(sweep: dict, results, interrupted: bool = False) -> list[dict]:
    """One row per trial: label, scene, seed, status (done, failed, stopped early by ASHA,
    unfinished where the sweep was interrupted), final eval reward, env steps, wall."""
    rows = []
    for r in results:
        m = r.metrics or {}
        cfg = r.config or {}
        t = cfg.get("trial") if sweep["kind"] == "grid" else None
        status = (
            "failed"
            if r.error is not None
            else "done"
            if m.get("finished")
            else "unfinished"
            if interrupted or t
            else "stopped early"
        )
        row = {
            "trial": t["label"] if t else (m.get("trial_id") or Path(r.path).name),
            "scene": scene_key(t["scene"] if t else sweep["scene"]),
            "seed": t["seed"] if t else sweep["seed"],
            "status": status,
            METRIC: m.get(METRIC),
            TIME_ATTR: m.get(TIME_ATTR),
            "wall_s": m.get("wall_s"),
            "values": {k: cfg.get(k) for k in sweep.get("space", {})},
        }
        rows.append(row)
    if sweep["kind"] == "grid":
        order = {t["label"]: i for i, t in enumerate(grid_trials(sweep))}
        rows.sort(key=lambda x: order.get(x["trial"], len(order)))
    else:
        rows.sort(
            key=lambda x: (
                -x[METRIC]
                if isinstance(x[METRIC], float) and math.isfinite(x[METRIC])
                else math.inf
            )
        )
    return rows


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def summary_table(rows: list[dict]) -> str:
    """The rows as an aligned text table (the searched values as extra columns)."""
    extra = list(rows[0]["values"]) if rows else []
    head = [
        "trial",
        "scene",
        "seed",
        *extra,
        "status",
        "final eval reward",
        "env steps",
        "wall [s]",
    ]
    body = [
        [
            r["trial"],
            r["scene"],
            _fmt(r["seed"]),
            *(_fmt(r["values"][k]) for k in extra),
            r["status"],
            _fmt(r[METRIC]),
            _fmt(r[TIME_ATTR]),
            "-" if r["wall_s"] is None else f"{r['wall_s']:.0f}",
        ]
        for r in rows
    ]
    widths = [max(len(x) for x in col) for col in zip(head, *body)]
    line = lambda cells: "  ".join(c.ljust(w) for c, w in zip(cells, widths)).rstrip()
    return "\n".join([line(head), line(["-" * w for w in widths])] + [line(b) for b in body])


def write_best(sweep: dict, rows: list[dict]) -> dict | None:
    """Write the best finished trial's entry into ``output`` (atomically, keyed by the scene;
    the file's other entries kept); the entry, or None where no trial finished."""
    done = [
        r
        for r in rows
        if r["status"] == "done" and isinstance(r[METRIC], float) and math.isfinite(r[METRIC])
    ]
    if not done:
        return None
    best = max(done, key=lambda r: r[METRIC])
    from rolling_env.env.scenes import read_yaml

    out = Path(sweep["output"])
    table = (read_yaml(out, "hyper-parameter file") or {}) if out.exists() else {}
    key = scene_key(sweep["scene"])
    entry = dict(sweep["base"], **_plain(best["values"]))
    table[key] = entry
    head = (
        f"# {sweep['algo']} on {key}: best of {len(rows)} trials of "
        f"`python -m agents.sweep` search {sweep['name']!r} ({sweep['n_timesteps']} env steps "
        f"each, seed {sweep['seed']}; last evaluation's mean reward {best[METRIC]:.4g}).\n"
        "# RL Zoo format; `python -m agents.train --algo "
        f"{sweep['algo']} --scene {key} --conf <this file>` trains it.\n"
    )
    text = head + yaml.safe_dump(table, sort_keys=False)
    atomic_write(out, lambda p: Path(p).write_text(text))
    return entry
