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
import os
import shlex
import shutil
import signal
import sys
import time
from pathlib import Path

import yaml

from .common import atomic_write, scene_key
from .sweep_file import (
    METRIC,
    PROG,
    SWEEP_FILE,
    TIME_ATTR,
    TRIAL_ENV,
    SweepError,
    check_start,
    experiment_dir,
    grid_trials,
    load_sweep,
)
from .sweep_results import _plain, _rows, summary_table, write_best


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
