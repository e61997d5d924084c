"""Run many trainings as one sweep on Ray Tune: a grid, or a hyper-parameter search.

    python -m agents.sweep --config configs/sweeps/<name>.yml [--address ADDRESS] [--resume]

A sweep file (YAML) says ``kind: grid`` or ``kind: search``.

* grid: scenes x agents x seeds.  The agents are ``algos`` (hyper-parameters from
  ``configs/hyperparams/<algo>.yml``) and ``configs`` (named configurations, each an algorithm
  and a hyper-parameter file).  Every trial trains in-process with ``agents.train.train``,
  the code behind ``python -m agents.train``, into the run folder that command would write,
  ``<runs>/<scene key>/<name>_seed<N>/``, so ``agents.evaluate --runs <runs>`` reads a
  sweep's output as it is.
* search: one algorithm on one scene; Optuna (``OptunaSearch``) samples the ``space`` over the
  scene's entry of the hyper-parameter file, ASHA (``ASHAScheduler``) stops poor trials early,
  both fed by the training's periodic evaluation (the mean reward of each evaluation, at its
  env step).  The best finished trial's entry (the base entry with the values found) is
  written, keyed by the scene, into ``output`` (RL Zoo format, atomically; other entries of
  the file are kept); ``python -m agents.train --algo A --scene S --conf <output>`` trains it.

Without ``--address`` a local Ray instance starts on this machine's cores; each trial asks
for ``cpus_per_trial`` (default 1) CPUs and runs numba and torch on one thread, so as many
trials run at once as there are cores.  ``--address`` joins a running cluster (``ray start
--head`` on one machine, ``ray start --address <head:port>`` on the others); every node then
needs the project installed and ``runs``, ``storage`` and ``output`` on a filesystem they all
share.

Tune's experiment state lives in ``<storage>/<name>/``.  Ctrl-C or SIGTERM stops the sweep
(exit 130 / 143) with the state saved; ``--resume`` continues it: finished trials are kept as
they are, trials that did not finish start again from scratch (their partial run folder is
replaced), and failed ones are tried again.  A trial that fails is retried up to
``max_failures`` times (default 1) while the others go on; a sweep with failed trials exits 1.
A bad sweep file is one line naming the key, exit 2, before Ray starts.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shlex
import shutil
import signal
import sys
import time
from pathlib import Path

import yaml

from .common import ALGOS, atomic_write, check_hyperparams, load_hyperparams, scene_key

PROG = "python -m agents.sweep"
# keys of a sweep file, with their defaults (None: none, or computed)
COMMON_KEYS = {
    "kind": None,
    "name": None,
    "storage": None,
    "n_timesteps": None,
    "n_envs": None,
    "eval_freq": 10000,
    "eval_episodes": 5,
    "checkpoint_freq": 50000,
    "cpus_per_trial": 1,
    "max_concurrent": 0,
    "max_failures": 1,
}
GRID_KEYS = dict(COMMON_KEYS, scenes=None, algos=[], configs={}, seeds=None, runs="runs")
SEARCH_KEYS = dict(
    COMMON_KEYS,
    scene=None,
    algo=None,
    conf=None,
    seed=0,
    trials=None,
    space=None,
    grace_period=None,
    reduction_factor=3,
    search_seed=0,
    output=None,
)
SPACE_KINDS = ("uniform", "loguniform", "int", "logint", "choice")
#: thread settings of every trial's process: one numba and one BLAS/OpenMP thread per trial
#: (a trial asks Ray for cpus_per_trial CPUs; more threads would oversubscribe the cores)
TRIAL_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
METRIC = "eval_reward"  # mean reward of the latest periodic evaluation
TIME_ATTR = "env_steps"
NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
SWEEP_FILE = "sweep.yml"  # the checked sweep, kept in the experiment folder for --resume


class SweepError(ValueError):
    """A bad sweep file or argument: one line, exit 2, found before Ray starts."""


# ------------------------------------------------------------------ the sweep file
def _number(key, v):
    """A YAML number; '3e-4' (which PyYAML reads as a string) counts as one."""
    if isinstance(v, str):
        try:
            v = float(v)
        except ValueError:
            pass
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SweepError(f"key {key!r} must be a number, got {v!r}")
    return v


def _int(key, v, lo=0, hi=10**12):
    x = _number(key, v)
    if x != int(x) or not lo <= x <= hi:
        raise SweepError(f"key {key!r} must be an integer in [{lo}, {hi}], got {v!r}")
    return int(x)


def _str(key, v):
    if not isinstance(v, str) or not v:
        raise SweepError(f"key {key!r} must be a non-empty string, got {v!r}")
    return v


def _name(key, v):
    if not isinstance(v, str) or not NAME.match(v):
        raise SweepError(
            f"key {key!r} must be a name of letters, digits, '_', '.' or '-', got {v!r}"
        )
    return v


def _list(key, v):
    if v is None:
        v = []
    if not isinstance(v, list):
        raise SweepError(f"key {key!r} must be a list, got {v!r}")
    return v


def _path(v) -> str:
    """Paths in a sweep file are relative to the current folder, as agents.train's flags are;
    trials get them absolute (a trial's working folder is its Tune trial folder)."""
    return str(Path(v).expanduser().absolute())


def _scene(key, s):
    from .common import buildable_scene

    s = _str(key, s)
    if Path(s).suffix.lower() in (".yaml", ".yml"):
        s = _path(s)
    try:
        buildable_scene(s)
    except ValueError as e:
        raise SweepError(f"key {key!r}: {e}") from None
    return s


def _entry(key, algo, scene, conf, n_timesteps, extra=None):
    """The scene's hyper-parameter entry, checked as agents.train checks it."""
    try:
        hp = load_hyperparams(algo, scene_key(scene), conf)
        checked = check_hyperparams(algo, dict(hp, **(extra or {})))
    except ValueError as e:
        raise SweepError(f"key {key!r}: {e}") from None
    if n_timesteps is None and checked["n_timesteps"] is None:
        raise SweepError(
            f"key {key!r}: the hyper-parameters of {algo} for scene "
            f"{scene_key(scene)!r} have no n_timesteps: give key 'n_timesteps'"
        )
    return hp


def _common(raw: dict, out: dict) -> None:
    out["n_timesteps"] = (
        None if raw.get("n_timesteps") is None else _int("n_timesteps", raw["n_timesteps"], 1)
    )
    out["n_envs"] = None if raw.get("n_envs") is None else _int("n_envs", raw["n_envs"], 1, 4096)
    for k in ("eval_freq", "eval_episodes", "checkpoint_freq"):
        out[k] = _int(k, raw[k], 1)
    cpus = _number("cpus_per_trial", raw["cpus_per_trial"])
    if not 0 < cpus <= 1024:
        raise SweepError(f"key 'cpus_per_trial' must be a number in (0, 1024], got {cpus!r}")
    out["cpus_per_trial"] = cpus
    out["max_concurrent"] = _int("max_concurrent", raw["max_concurrent"], 0, 10**6)
    out["max_failures"] = _int("max_failures", raw["max_failures"], 0, 100)


def _grid(raw: dict, out: dict) -> None:  # noqa: C901 (one check per key of a grid file)
    from .train import SEED_MAX

    scenes = _list("scenes", raw["scenes"])
    if not scenes:
        raise SweepError("key 'scenes' is empty or missing: the grid has no trials")
    out["scenes"], keys = [], {}
    for s in scenes:
        s = _scene("scenes", s)
        k = scene_key(s)
        if k in keys:
            raise SweepError(
                f"key 'scenes': {keys[k]!r} and {s!r} have the same scene key "
                f"{k!r} (their run folders would collide)"
            )
        keys[k] = s
        out["scenes"].append(s)
    agents = {}
    for a in _list("algos", raw["algos"]):
        if a not in ALGOS:
            raise SweepError(f"key 'algos': unknown algorithm {a!r} (one of {list(ALGOS)})")
        if a in agents:
            raise SweepError(f"key 'algos': {a!r} given twice")
        agents[a] = {"algo": a, "conf": None}
    configs = raw["configs"] if raw["configs"] is not None else {}
    if not isinstance(configs, dict):
        raise SweepError(
            f"key 'configs' must be a mapping of name: {{algo, conf}}, got {configs!r}"
        )
    for name, c in configs.items():
        key = f"configs.{name}"
        _name("configs", name)
        if name in agents:
            raise SweepError(
                f"key {key!r}: the name is also in 'algos' (run folders "
                f"{name}_seed<N> would collide)"
            )
        if not isinstance(c, dict) or "algo" not in c:
            raise SweepError(f"key {key!r} must be a mapping with 'algo' and 'conf', got {c!r}")
        bad = sorted(set(c) - {"algo", "conf"})
        if bad:
            raise SweepError(
                f"key '{key}.{bad[0]}' unknown (a configuration has 'algo' and 'conf')"
            )
        if c["algo"] not in ALGOS:
            raise SweepError(
                f"key '{key}.algo': unknown algorithm {c['algo']!r} (one of {list(ALGOS)})"
            )
        agents[name] = {
            "algo": c["algo"],
            "conf": None if c.get("conf") is None else _path(_str(f"{key}.conf", c["conf"])),
        }
    if not agents:
        raise SweepError(
            "keys 'algos' and 'configs' are both empty or missing: the grid has no trials"
        )
    out["agents"] = agents
    seeds = _list("seeds", raw["seeds"])
    if not seeds:
        raise SweepError("key 'seeds' is empty or missing: the grid has no trials")
    out["seeds"] = [_int("seeds", s, 0, SEED_MAX) for s in seeds]
    if len(set(out["seeds"])) != len(out["seeds"]):
        raise SweepError(f"key 'seeds': a seed is given twice in {out['seeds']}")
    for name, a in agents.items():  # every entry checked, as agents.train checks it
        for s in out["scenes"]:
            _entry(
                "configs." + name if name in configs else "algos",
                a["algo"],
                s,
                a["conf"],
                out["n_timesteps"],
            )
    out["runs"] = _path(_str("runs", raw["runs"]))
    out["storage"] = _path(
        raw["storage"] if raw.get("storage") is not None else Path(out["runs"]) / ".sweeps"
    )


def _space(key: str, spec) -> tuple:
    """One dimension of the search space: ({kind: args}) -> (kind, args), checked."""
    if not isinstance(spec, dict) or len(spec) != 1 or next(iter(spec)) not in SPACE_KINDS:
        raise SweepError(
            f"key {key!r} must be one of {{{', '.join(SPACE_KINDS)}: ...}}, got {spec!r}"
        )
    kind, args = next(iter(spec.items()))
    if kind == "choice":  # Optuna's categorical values are scalars
        if (
            not isinstance(args, list)
            or not args
            or not all(a is None or isinstance(a, (str, int, float)) for a in args)
        ):
            raise SweepError(
                f"key {key!r}: choice needs a non-empty list of numbers, strings "
                f"or booleans, got {args!r}"
            )
        return kind, args
    if not isinstance(args, list) or len(args) != 2:
        raise SweepError(f"key {key!r}: {kind} needs [low, high], got {args!r}")
    lo, hi = (
        _int(key, a, -(10**12)) if kind in ("int", "logint") else _number(key, a) for a in args
    )
    if not lo < hi or (kind.startswith("log") and lo <= 0):
        raise SweepError(
            f"key {key!r}: {kind} needs low < high"
            + (" and low > 0" if kind.startswith("log") else "")
            + f", got {args!r}"
        )
    return kind, [lo, hi]


def _search(raw: dict, out: dict) -> None:
    from .train import SEED_MAX

    if raw["scene"] is None:
        raise SweepError("key 'scene' is missing: a search runs on one scene")
    out["scene"] = _scene("scene", raw["scene"])
    if raw["algo"] not in ALGOS:
        raise SweepError(f"key 'algo': unknown algorithm {raw['algo']!r} (one of {list(ALGOS)})")
    out["algo"] = raw["algo"]
    out["conf"] = None if raw["conf"] is None else _path(_str("conf", raw["conf"]))
    out["seed"] = _int("seed", raw["seed"], 0, SEED_MAX)
    if raw["trials"] is None:
        raise SweepError("key 'trials' is missing: how many configurations to try")
    out["trials"] = _int("trials", raw["trials"], 1, 100000)
    if out["n_timesteps"] is None:
        raise SweepError("key 'n_timesteps' is missing: the budget of each trial")
    if out["eval_freq"] > out["n_timesteps"]:
        raise SweepError(
            f"key 'eval_freq' ({out['eval_freq']}) is larger than n_timesteps "
            f"({out['n_timesteps']}): the search needs evaluations"
        )
    space = raw["space"]
    if not isinstance(space, dict) or not space:
        raise SweepError(
            f"key 'space' must be a non-empty mapping of hyper-parameter: "
            f"{{{', '.join(SPACE_KINDS)}: ...}}, got {space!r}"
        )
    base = _entry("conf", out["algo"], out["scene"], out["conf"], out["n_timesteps"])
    out["space"] = {}
    for k, spec in space.items():
        key = f"space.{k}"
        if k in ("n_timesteps", "env_kwargs") or (k == "n_envs" and out["n_envs"]):
            raise SweepError(
                f"key {key!r} cannot be searched ("
                + {
                    "n_timesteps": "the budget is key 'n_timesteps'",
                    "env_kwargs": "scene overrides would change the scene",
                    "n_envs": "key 'n_envs' fixes it for every trial",
                }[k]
                + ")"
            )
        kind, args = _space(key, spec)
        for v in args:  # the ends of a range and every choice must pass the entry's check
            _entry(key, out["algo"], out["scene"], out["conf"], out["n_timesteps"], {k: v})
        out["space"][str(k)] = {kind: args}
    out["base"] = base
    gp = raw["grace_period"]
    out["grace_period"] = (
        max(out["eval_freq"], out["n_timesteps"] // 4)
        if gp is None
        else _int("grace_period", gp, 1, out["n_timesteps"])
    )
    out["reduction_factor"] = _int("reduction_factor", raw["reduction_factor"], 2, 100)
    out["search_seed"] = _int("search_seed", raw["search_seed"], 0, 2**32 - 1)
    if raw["output"] is None:
        raise SweepError("key 'output' is missing: the YAML file the best entry is written to")
    out["output"] = _path(_str("output", raw["output"]))
    if Path(out["output"]).suffix.lower() not in (".yml", ".yaml"):
        raise SweepError(f"key 'output' must name a .yml file, got {raw['output']!r}")
    if Path(out["output"]).exists():  # its other entries are kept: it must be readable
        from rolling_env.scenes import read_yaml

        try:
            table = read_yaml(out["output"], "hyper-parameter file")
        except ValueError as e:
            raise SweepError(f"key 'output': {e}") from None
        if table is not None and not isinstance(table, dict):
            raise SweepError(f"key 'output': {raw['output']!r} holds no mapping of entries")
    out["storage"] = _path(
        raw["storage"] if raw.get("storage") is not None else Path("runs") / ".sweeps"
    )


def load_sweep(path) -> dict:
    """The sweep file at ``path``, checked: every key known and typed, every scene buildable,
    every algorithm known, every hyper-parameter entry (and every end of the search space)
    accepted as agents.train would accept it, the grid not empty.  A SweepError naming the
    key otherwise.  Paths come back absolute."""
    from rolling_env.scenes import read_yaml

    try:
        raw = read_yaml(path, "sweep file")
    except ValueError as e:
        raise SweepError(str(e)) from None
    if not isinstance(raw, dict):
        raise SweepError(
            f"sweep file {str(path)!r} must hold a mapping of keys, got {type(raw).__name__}"
        )
    kind = raw.get("kind")
    if kind not in ("grid", "search"):
        raise SweepError(f"key 'kind' must be 'grid' or 'search', got {kind!r}")
    known = GRID_KEYS if kind == "grid" else SEARCH_KEYS
    unknown = [k for k in raw if k not in known]
    if unknown:
        raise SweepError(
            f"key {unknown[0]!r} is unknown for a {kind} sweep (keys: {', '.join(known)})"
        )
    raw = {k: raw.get(k, d) for k, d in known.items()}
    out = {
        "kind": kind,
        "name": _name("name", raw["name"] if raw["name"] is not None else Path(path).stem),
    }
    _common(raw, out)
    (_grid if kind == "grid" else _search)(raw, out)
    return out


def grid_trials(sweep: dict) -> list[dict]:
    """The grid's trials, scene-major: label, scene, agent name, algorithm, conf, seed, run
    folder."""
    out = []
    for s in sweep["scenes"]:
        key = scene_key(s)
        for name, a in sweep["agents"].items():
            for seed in sweep["seeds"]:
                run = Path(sweep["runs"]) / key / f"{name}_seed{seed}"
                out.append(
                    {
                        "label": f"{key}/{name}_seed{seed}",
                        "scene": s,
                        "name": name,
                        "algo": a["algo"],
                        "conf": a["conf"],
                        "seed": seed,
                        "run_dir": str(run),
                    }
                )
    return out


def experiment_dir(sweep: dict) -> Path:
    return Path(sweep["storage"]) / sweep["name"]


def _has_state(exp: Path) -> bool:
    """Whether Tune has saved an experiment in ``exp`` (what Tuner.restore needs)."""
    return (exp / "tuner.pkl").is_file()


def _differs(a, b, prefix="") -> str | None:
    """The first key where two checked sweeps differ, None where they do not."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in list(a) + [k for k in b if k not in a]:
            d = _differs(a.get(k), b.get(k), f"{prefix}{k}.")
            if d:
                return d
        return None
    return None if a == b else prefix.rstrip(".")


def check_start(sweep: dict, resume: bool) -> None:
    """What must hold before Ray starts: a new sweep has no earlier state and its run folders
    are empty; a resumed one has state, from the same sweep file content."""
    exp = experiment_dir(sweep)
    if resume:
        if not _has_state(exp):
            raise SweepError(
                f"--resume: no sweep to resume in {str(exp)!r} (start it without --resume)"
            )
        saved = exp / SWEEP_FILE
        if saved.is_file():
            before = yaml.safe_load(saved.read_text())
            key = _differs(before, json.loads(json.dumps(sweep)))
            if key:
                raise SweepError(
                    f"--resume: key {key!r} differs from the sweep started in "
                    f"{str(exp)!r}: resume with the file as it was, or start a "
                    "new sweep under another name"
                )
        return
    if _has_state(exp):
        raise SweepError(
            f"a sweep named {sweep['name']!r} was already started in {str(exp)!r}:"
            " --resume continues it; another 'name' or 'storage' starts a new one"
        )
    if sweep["kind"] == "grid":
        for t in grid_trials(sweep):
            run = Path(t["run_dir"])
            if run.is_symlink() or (run.exists() and (not run.is_dir() or any(run.iterdir()))):
                raise SweepError(
                    f"run folder {t['run_dir']!r} already exists and is not "
                    "empty: choose another 'runs' folder, or move it away"
                )


# ------------------------------------------------------------------ one trial (a Ray worker)
def _one_thread() -> None:
    """One numba and one BLAS thread in this trial's process (set before numba or torch is
    imported here; the runtime env of ``ray.init`` sets the same for every worker)."""
    for k, v in TRIAL_ENV.items():
        os.environ[k] = v
    if "numba" in sys.modules:
        import numba

        if numba.config.NUMBA_NUM_THREADS > 1:
            numba.set_num_threads(1)


def run_result(run: Path) -> dict:
    """What a finished run folder says: the last evaluation's mean reward, env steps, wall
    time (meta.json's, the training alone)."""
    import numpy as np

    meta = json.loads((run / "meta.json").read_text())
    reward = float("nan")
    if (run / "evaluations.npz").is_file():
        with np.load(run / "evaluations.npz") as ev:
            if len(ev["results"]):
                reward = float(np.mean(ev["results"][-1]))
    return {
        METRIC: reward,
        TIME_ATTR: int(meta["env_steps"]),
        "wall_s": float(meta["wall_seconds"]),
        "finished": True,
        "run_dir": str(run),
    }


def _finished(run: Path, algo: str, seed: int, key: str) -> dict | None:
    """The result of ``run`` where it holds this trial's finished training (a trial that
    finished while the sweep was being stopped, before Tune recorded it), else None."""
    from .common import run_config

    try:
        meta = json.loads((run / "meta.json").read_text())
        cfg = run_config(run)
    except (OSError, ValueError):
        return None
    if (
        meta.get("interrupted") is not False
        or not (run / "model.zip").is_file()
        or not cfg
        or (cfg.get("algo"), cfg.get("seed"), cfg.get("scene_key")) != (algo, seed, key)
    ):
        return None
    return run_result(run)


def _clear(run: Path) -> None:
    """Remove what an unfinished attempt of this trial left in ``run`` (only a folder that
    agents.train created and that holds nothing but its files)."""
    from .train import _not_a_run

    if not (run.exists() or run.is_symlink()) or (
        run.is_dir() and not run.is_symlink() and not any(run.iterdir())
    ):
        return
    why = _not_a_run(run)
    if why:
        raise RuntimeError(f"run folder {str(run)!r} {why}: it is not replaced")
    shutil.rmtree(run)


def run_trial(config: dict, spec: dict) -> None:
    """A Tune function trainable: train one run with agents.train's code, report each
    periodic evaluation (``eval_reward`` at ``env_steps``) and, at the end, the finished
    run's result.  ``config``: a grid's ``{"trial": ...}`` or a search's sampled values;
    ``spec``: the rest of the sweep."""
    _one_thread()
    from ray import tune

    from . import train as T

    if spec["kind"] == "grid":
        t = config["trial"]
        run, algo, scene, seed, conf = (
            Path(t["run_dir"]),
            t["algo"],
            t["scene"],
            t["seed"],
            t["conf"],
        )
    else:
        algo, scene, seed = spec["algo"], spec["scene"], spec["seed"]
        trial_id = tune.get_context().get_trial_id()
        run = Path(spec["trials_dir"]) / trial_id
        conf = str(run.with_name(trial_id + ".hyperparams.yml"))
        entry = dict(spec["base"], **_plain(config))
        atomic_write(
            conf,
            lambda p: Path(p).write_text(
                yaml.safe_dump({scene_key(scene): entry}, sort_keys=False)
            ),
        )
    done = _finished(run, algo, seed, scene_key(scene))
    if done is not None:
        tune.report(done)
        return
    _clear(run)
    argv = [
        "--algo",
        algo,
        "--scene",
        str(scene),
        "--seed",
        str(seed),
        "--run-dir",
        str(run),
        "--eval-freq",
        str(spec["eval_freq"]),
        "--eval-episodes",
        str(spec["eval_episodes"]),
        "--checkpoint-freq",
        str(spec["checkpoint_freq"]),
        "--no-progress",
    ]
    if conf:
        argv += ["--conf", conf]
    for k in ("n_timesteps", "n_envs"):
        if spec[k] is not None:
            argv += ["--" + k.replace("_", "-"), str(spec[k])]
    args = T.build_parser().parse_args(argv)
    T.train(
        args,
        command="python -m agents.train " + shlex.join(argv),
        on_eval=lambda steps, reward: tune.report({METRIC: reward, TIME_ATTR: steps}),
    )
    tune.report(run_result(run))


def _plain(d: dict) -> dict:
    """Sampled values as plain Python (numpy scalars would not dump as YAML)."""
    return {k: (v.item() if hasattr(v, "item") else v) for k, v in d.items()}


def trial_dirname(trial) -> str:
    """Tune trial folders named after the trial (grid) or its id (search)."""
    t = trial.config.get("trial")
    label = t["label"].replace("/", "-") if isinstance(t, dict) else "trial"
    return f"{label}_{trial.trial_id}"


def trial_name(trial) -> str:
    t = trial.config.get("trial")
    return t["label"] if isinstance(t, dict) else trial.trial_id


# ------------------------------------------------------------------ the driver
def _progress_callback(total: int):
    """One line per trial that finishes, stops early, fails or is retried (Tune's own status
    tables are switched off)."""
    from ray import tune

    class Progress(tune.Callback):
        def setup(self, **info):
            self.t0 = time.perf_counter()

        def _line(self, trials, trial, what, ended=True):
            # trials ended so far, this one included where it has ended (Tune sets its status
            # after the callbacks)
            n = ended + sum(t.status in ("TERMINATED", "ERROR") for t in trials if t is not trial)
            r = trial.last_result or {}
            reward = r.get(METRIC)
            tail = (
                ""
                if reward is None
                else (
                    f": eval reward {reward:.4g} at {r.get(TIME_ATTR)} env steps"
                    + (f", {r['wall_s']:.0f} s" if "wall_s" in r else "")
                )
            )
            print(
                f"[{time.perf_counter() - getattr(self, 't0', time.perf_counter()):6.0f} s] "
                f"{n}/{total} {trial_name(trial)} {what}{tail}",
                flush=True,
            )

        def on_trial_complete(self, iteration, trials, trial, **info):
            r = trial.last_result or {}
            self._line(trials, trial, "finished" if r.get("finished") else "stopped early")

        def on_trial_recover(self, iteration, trials, trial, **info):
            self._line(
                trials,
                trial,
                f"failed, retrying (failure {trial.num_failures}): {_error_line(trial)}",
                ended=False,
            )

        def on_trial_error(self, iteration, trials, trial, **info):
            self._line(
                trials,
                trial,
                f"FAILED ({trial.num_failures} failures): "
                f"{_error_line(trial)}; log: {trial.error_file}",
            )

    return Progress()


def _error_line(trial) -> str:
    try:
        lines = [x for x in Path(trial.error_file).read_text().splitlines() if x.strip()]
        return lines[-1].strip()[:300] if lines else "error"
    except (OSError, TypeError):
        return "error"


def _install_stop_handlers() -> dict:
    """Ctrl-C and SIGTERM stop the sweep as Tune's own stop signal (SIGUSR1) does: the
    running trials end, the experiment state is saved, and fit() returns; a second signal
    stops at once.  Returns the record of the signals received."""
    got = {"signals": []}

    def handler(signum, frame):
        got["signals"].append(signum)
        tune_handler = signal.getsignal(signal.SIGUSR1)
        if len(got["signals"]) == 1 and callable(tune_handler):
            print(
                f"{PROG}: stopping: the trials that run now are stopped, the sweep's state "
                "is saved (--resume continues it); send the signal again to stop at once",
                file=sys.stderr,
                flush=True,
            )
            signal.raise_signal(signal.SIGUSR1)
        else:
            raise KeyboardInterrupt

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return got


def _start_ray(address: str | None):
    import logging

    import ray

    logging.getLogger("ray").setLevel(logging.WARNING)
    # Tune's advice on stopping and resuming names its Python API; ours names --resume
    logging.getLogger("ray.tune.tune").setLevel(logging.ERROR)
    kw = {
        "log_to_driver": False,
        "logging_level": logging.WARNING,
        "runtime_env": {"env_vars": dict(TRIAL_ENV)},
    }
    if address:
        ray.init(address=address, **kw)
    else:  # a local instance on this machine's cores
        ray.init(include_dashboard=False, **kw)
    return ray


def _tuner(sweep: dict, resume: bool, progress):
    """Tune's Tuner for the sweep, or the saved one restored."""
    from ray import tune

    exp = experiment_dir(sweep)
    spec = {
        k: sweep[k]
        for k in ("kind", "n_timesteps", "n_envs", "eval_freq", "eval_episodes", "checkpoint_freq")
    }
    if sweep["kind"] == "search":
        spec.update(
            algo=sweep["algo"],
            scene=sweep["scene"],
            seed=sweep["seed"],
            base=sweep["base"],
            trials_dir=str(exp / "trials"),
        )
    trainable = tune.with_resources(
        tune.with_parameters(run_trial, spec=spec), {"cpu": sweep["cpus_per_trial"]}
    )
    if resume:  # unfinished trials start again, failed ones are tried again, from scratch
        return tune.Tuner.restore(str(exp), trainable, resume_unfinished=True, restart_errored=True)
    run_config = tune.RunConfig(
        name=sweep["name"],
        storage_path=sweep["storage"],
        verbose=0,
        callbacks=[progress],
        failure_config=tune.FailureConfig(max_failures=sweep["max_failures"]),
    )
    common = {
        "reuse_actors": True,
        "max_concurrent_trials": sweep["max_concurrent"] or None,
        "trial_name_creator": trial_name,
        "trial_dirname_creator": trial_dirname,
    }
    if sweep["kind"] == "grid":
        return tune.Tuner(
            trainable,
            param_space={"trial": tune.grid_search(grid_trials(sweep))},
            tune_config=tune.TuneConfig(**common),
            run_config=run_config,
        )
    import optuna
    from ray.tune.schedulers import ASHAScheduler
    from ray.tune.search.optuna import OptunaSearch

    optuna.logging.set_verbosity(optuna.logging.WARNING)  # one line per trial is ours
    dims = {
        "uniform": tune.uniform,
        "loguniform": tune.loguniform,
        "choice": tune.choice,
        "int": lambda lo, hi: tune.randint(lo, hi + 1),  # Tune's upper end is exclusive
        "logint": lambda lo, hi: tune.lograndint(lo, hi + 1),
    }
    space = {}
    for k, d in sweep["space"].items():
        kind, args = next(iter(d.items()))
        space[k] = dims[kind](args) if kind == "choice" else dims[kind](*args)
    # ASHA stops poor trials at its rungs only: a trial that passes them ends when its
    # training does (its final model saved), not at max_t
    scheduler = ASHAScheduler(
        time_attr=TIME_ATTR,
        max_t=sweep["n_timesteps"],
        grace_period=sweep["grace_period"],
        reduction_factor=sweep["reduction_factor"],
        stop_last_trials=False,
    )
    return tune.Tuner(
        trainable,
        param_space=space,
        run_config=run_config,
        tune_config=tune.TuneConfig(
            metric=METRIC,
            mode="max",
            num_samples=sweep["trials"],
            search_alg=OptunaSearch(seed=sweep["search_seed"]),
            scheduler=scheduler,
            **common,
        ),
    )


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
    from rolling_env.scenes import read_yaml

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


def build_parser():
    p = argparse.ArgumentParser(prog=PROG, description=__doc__.splitlines()[0])
    p.add_argument("--config", required=True, help="sweep file (YAML), e.g. configs/sweeps/...")
    p.add_argument(
        "--address",
        default=None,
        help="join this Ray cluster (e.g. 'auto' or 'head-node:6379'); default: a "
        "local Ray instance on this machine's cores",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the sweep saved in <storage>/<name>/: finished trials are "
        "kept, unfinished and failed ones run again",
    )
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:  # everything about the file, before Ray starts
        sweep = load_sweep(args.config)
        check_start(sweep, args.resume)
        try:
            import ray.tune

            if sweep["kind"] == "search":
                import optuna  # noqa: F401
        except ImportError as e:
            raise SweepError(f'{e.name} is not installed: pip install -e ".[sweep]"') from None
    except SweepError as e:
        where = "" if str(e).startswith("--resume") else f"{args.config}: "
        print(f"{PROG}: error: {where}{e}", file=sys.stderr)
        return 2
    exp = experiment_dir(sweep)
    total = len(grid_trials(sweep)) if sweep["kind"] == "grid" else sweep["trials"]
    # Tune's SIGINT handler is replaced by ours (which also takes SIGTERM)
    os.environ["TUNE_DISABLE_SIGINT_HANDLER"] = "1"
    os.environ.setdefault("RAY_AIR_NEW_OUTPUT", "0")  # no status tables: one line per trial
    ray = _start_ray(args.address)
    try:
        got = _install_stop_handlers()  # after ray.init, which sets its own SIGTERM handler
        if not args.resume:
            atomic_write(
                exp / SWEEP_FILE,
                lambda p: Path(p).write_text(
                    yaml.safe_dump(json.loads(json.dumps(sweep)), sort_keys=False)
                ),
            )
        cpus = ray.cluster_resources().get("CPU", 0)
        print(
            f"{PROG}: {sweep['kind']} {sweep['name']!r}: {total} trials, "
            f"{sweep['cpus_per_trial']:g} CPU each, {cpus:g} CPUs "
            f"({'cluster ' + args.address if args.address else 'local'}); state in "
            f"{str(exp)!r}" + (" (resumed)" if args.resume else ""),
            flush=True,
        )
        t0 = time.perf_counter()
        results = _tuner(sweep, args.resume, _progress_callback(total)).fit()
        wall = time.perf_counter() - t0
        rows = _rows(sweep, results, bool(got["signals"]))
        print()
        print(summary_table(rows))
        n_done = sum(r["status"] == "done" for r in rows)
        n_failed = sum(r["status"] == "failed" for r in rows)
        print(
            f"\n{n_done} of {len(rows)} trials finished, {n_failed} failed; {wall:.0f} s "
            "(this invocation)",
            flush=True,
        )
        if got["signals"]:
            print(
                f"{PROG}: interrupted; continue with: {PROG} --config {args.config} --resume"
                + (f" --address {args.address}" if args.address else ""),
                file=sys.stderr,
            )
            return 128 + got["signals"][0]
        if sweep["kind"] == "search":
            entry = write_best(sweep, rows)
            if entry is None:
                print(
                    f"{PROG}: no trial finished: nothing written to {sweep['output']!r}",
                    file=sys.stderr,
                )
                return 1
            print(
                f"best entry for {scene_key(sweep['scene'])!r} written to "
                f"{sweep['output']!r}: " + json.dumps({k: entry[k] for k in sweep["space"]})
            )
        return 1 if n_failed else 0
    except KeyboardInterrupt:  # the second signal: Tune's state is what it saved last
        print(
            f"{PROG}: stopped at once; --resume continues from the last saved state",
            file=sys.stderr,
        )
        return 130
    finally:
        ray.shutdown()


if __name__ == "__main__":
    sys.exit(main())
