"""The sweep file of ``python -m agents.sweep``: reading and checking a grid or a search (one
line naming the key for anything wrong, before Ray starts), the grid's trials, the experiment
folder and what ``--resume`` may continue."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import yaml

from .common import ALGOS, load_hyperparams, scene_key
from .hyperparams import check_hyperparams

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
        from rolling_env.env.scenes import read_yaml

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
    from rolling_env.env.scenes import read_yaml

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
