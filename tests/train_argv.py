"""The argument list of a tiny ``agents.train`` run for the tests: PPO for a few env steps,
one evaluation episode, no progress bar."""


def tiny_ppo_argv(*extra: str, timesteps: int = 64, n_envs: int = 1, eval_freq=None) -> list:
    """``agents.train`` arguments for PPO over ``timesteps`` env steps on ``n_envs`` envs,
    evaluated every ``eval_freq`` steps (default: once, at the end) on one episode; ``extra``
    follows (scene, seed, run folder, ...)."""
    return [
        *("--algo", "ppo", "--n-timesteps", str(timesteps), "--n-envs", str(n_envs)),
        *("--eval-freq", str(eval_freq or timesteps), "--eval-episodes", "1", "--no-progress"),
        *extra,
    ]
