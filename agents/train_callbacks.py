"""The callbacks of a training run: periodic atomic checkpoints, and the periodic evaluation
with its logs (EvalCallback's ``evaluations.npz``, the best model with its statistics, and
``GOAL_LOG`` for the time to goal)."""

from __future__ import annotations

import json
import time
from pathlib import Path

from .common import atomic_write, save_model

GOAL_LOG = "eval_goal.json"  # final errors and slip work of the periodic evaluations


class _AtomicCheckpoint:
    """SB3 callback factory: periodic atomic checkpoints (model + VecNormalize)."""

    @staticmethod
    def make(folder, every_env_steps):
        from stable_baselines3.common.callbacks import BaseCallback

        class Cb(BaseCallback):
            def _on_step(self):
                n = self.model.num_timesteps
                if n // every_env_steps > getattr(self, "_last", 0):
                    self._last = n // every_env_steps
                    save_model(self.model, self.model.get_vec_normalize_env(), folder, "checkpoint")
                return True

        return Cb()


def ticks_per_step(venv) -> int:
    """Env ticks in one step of a (wrapped) training env: a period-level env's period, else
    1 (its steps are the env's ticks)."""
    while venv is not None:
        ex = getattr(venv, "excitation", None)
        if ex is not None:
            return int(ex.ticks)
        venv = getattr(venv, "venv", None)
    return 1


class _GoalEpisodes:
    """Mixed into SB3's EvalCallback: also keeps, per evaluation episode, the final |error|
    [m] and the slip work [J] (from the single env's info), for the time to goal."""

    def _on_step(self):
        if self.eval_freq > 0 and self.n_calls % self.eval_freq == 0:  # evaluates now
            self._goal_eps, self._slip = [], {}
        return super()._on_step()

    def _log_success_callback(self, locals_, globals_):
        super()._log_success_callback(locals_, globals_)
        info, i = locals_["info"], locals_["i"]
        self._slip[i] = self._slip.get(i, 0.0) + float(info.get("slip_work", 0.0))
        if locals_["done"] and "xstar" in info:
            self._goal_eps.append(
                (abs(float(info["target"]) - float(info["xstar"])), self._slip.pop(i))
            )


def _log_goal(run: Path, log: list, eps: list, env_steps: int, wall: float, tol, reward):
    """Append one evaluation's episodes ``eps`` ((final |error|, slip work) pairs) to ``log``
    and write it to ``run/GOAL_LOG``; with a tolerance ``tol``, print one line on it."""
    log.append(
        {
            "env_steps": env_steps,
            "wall_seconds": round(wall, 2),
            "final_abs_error": [e for e, _ in eps],
            "slip_work": [w for _, w in eps],
        }
    )
    atomic_write(run / GOAL_LOG, lambda p: Path(p).write_text(json.dumps(log)))
    if tol:  # one line per evaluation: what a user watches a run by
        err = sum(e for e, _ in eps) / len(eps) / tol
        slip = sum(w for _, w in eps) / len(eps)
        print(
            f"eval at {env_steps:,} env steps: mean reward "
            f"{reward:.2f}, final |error| {err:.2f} "
            f"tolerance, slip work {slip:.3g} J",
            flush=True,
        )


def _eval_callback(
    eval_env, run: Path, eval_freq: int, n_episodes: int, on_eval=None, tol: float | None = None
):
    """SB3's EvalCallback with every file written atomically: it logs to a scratch folder
    (``run/.eval_scratch``, removed at the end) and after each evaluation the log is copied
    atomically to ``run/evaluations.npz``; a new best model is saved atomically as
    ``best_model.zip`` with the VecNormalize statistics of that moment beside it
    (``best_model_vecnormalize.pkl``: the statistics it was selected with).  ``GOAL_LOG``
    keeps, per evaluation, the env steps, the wall time since the start of training and
    each episode's final |error| and slip work (``agents.evaluate``'s time to goal).  ``on_eval``,
    if given, is called after each evaluation with (steps of the training env, as
    ``n_timesteps`` counts them, and the mean eval reward)."""
    from stable_baselines3.common.callbacks import BaseCallback, EvalCallback

    scratch = run / ".eval_scratch"
    t0 = time.perf_counter()
    per_step = ticks_per_step(eval_env)  # env steps (ticks) in a step of the training env
    log: list = []

    class GoalEval(_GoalEpisodes, EvalCallback):
        pass

    class OnNewBest(BaseCallback):
        def _on_step(self):
            save_model(self.model, self.model.get_vec_normalize_env(), run, "best_model")
            return True

    class AfterEval(BaseCallback):
        def _on_step(self):
            src = scratch / "evaluations.npz"
            if src.exists():
                atomic_write(
                    run / "evaluations.npz", lambda p: Path(p).write_bytes(src.read_bytes())
                )
            eps = getattr(self.parent, "_goal_eps", [])
            if eps:
                steps = int(self.num_timesteps) * per_step
                wall = time.perf_counter() - t0
                _log_goal(run, log, eps, steps, wall, tol, self.parent.last_mean_reward)
            if on_eval is not None:
                on_eval(int(self.num_timesteps), float(self.parent.last_mean_reward))
            return True

    return GoalEval(
        eval_env,
        best_model_save_path=None,
        log_path=str(scratch),
        eval_freq=eval_freq,
        n_eval_episodes=n_episodes,
        deterministic=True,
        verbose=0,
        callback_on_new_best=OnNewBest(),
        callback_after_eval=AfterEval(),
    )
