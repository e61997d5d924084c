"""Hyper-parameters of an RL Zoo entry, checked: every key an RL Zoo key the scripts handle or
a keyword of the algorithm's ``__init__``, typed as SB3 annotates it and in range; RL Zoo's
kwargs strings parsed without eval; ``policy_kwargs`` and action noise."""

from __future__ import annotations

import ast
import re

from .common import one_line


# ----------------------------------------------------------------- RL Zoo kwargs strings
def _torch_attr(parts: list[str]):
    """``nn.ReLU`` / ``torch.nn.ReLU`` / ``th.optim.Adam``: a torch.nn module class or a
    torch.optim optimizer class, nothing else (RL Zoo writes activations this way)."""
    import torch

    if parts[:1] in (["torch"], ["th"]):
        parts = parts[1:]
    if len(parts) == 2 and parts[0] in ("nn", "optim"):
        base = torch.nn.Module if parts[0] == "nn" else torch.optim.Optimizer
        obj = getattr(getattr(torch, parts[0]), parts[1], None)
        if isinstance(obj, type) and issubclass(obj, base):
            return obj
    raise ValueError(
        f"{'.'.join(parts)!r} is not a torch.nn module or torch.optim optimizer "
        "class (allowed names: nn.X, torch.nn.X, th.nn.X, optim.X, th.optim.X)"
    )


def _literal(node):
    """A safe subset of Python: literals, lists, tuples, dicts, ``dict(k=v, ...)`` and torch
    class names (``_torch_attr``).  Nothing is evaluated."""
    if isinstance(node, ast.Constant):
        return node.value
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        v = _literal(node.operand)
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return -v if isinstance(node.op, ast.USub) else v
    if isinstance(node, (ast.List, ast.Tuple)):
        items = [_literal(e) for e in node.elts]
        return items if isinstance(node, ast.List) else tuple(items)
    if isinstance(node, ast.Dict) and None not in node.keys:
        return {_literal(k): _literal(v) for k, v in zip(node.keys, node.values)}
    if (
        isinstance(node, ast.Call)
        and isinstance(node.func, ast.Name)
        and node.func.id == "dict"
        and not node.args
        and all(kw.arg is not None for kw in node.keywords)
    ):
        return {kw.arg: _literal(kw.value) for kw in node.keywords}
    if isinstance(node, ast.Attribute):
        parts = []
        while isinstance(node, ast.Attribute):
            parts.insert(0, node.attr)
            node = node.value
        if isinstance(node, ast.Name):
            return _torch_attr([node.id] + parts)
    raise ValueError(
        f"{ast.unparse(node)!r} is not allowed (only literals, lists, dict(...), "
        "{...} and torch classes such as nn.ReLU)"
    )


_TORCH_NAME = re.compile(r"^((torch|th)\.)?(nn|optim)\.\w+$")


def parse_kwargs(text) -> dict | None:
    """RL Zoo writes policy_kwargs / normalize as Python in strings: "dict(net_arch=[64],
    activation_fn=nn.ReLU)".  Parsed safely (``_literal``: literals, dict(...), nn.X; never
    eval); a YAML mapping is taken with its torch class names (``activation_fn: nn.ReLU``)
    resolved the same way, None as {}, True as {} and False as None (normalize)."""
    if text is None:
        return {}
    if isinstance(text, dict):
        return {
            k: _torch_attr(v.split(".")) if isinstance(v, str) and _TORCH_NAME.match(v) else v
            for k, v in text.items()
        }
    if isinstance(text, bool):
        return {} if text else None
    if not isinstance(text, str):
        raise ValueError(f'must be a mapping or a string such as "dict(a=1)", got {text!r}')
    try:
        node = ast.parse(text.strip(), mode="eval").body
    except SyntaxError as e:
        raise ValueError(f"is not valid Python ({e.msg}): {text!r}") from None
    value = _literal(node)
    if isinstance(value, bool):
        return {} if value else None
    if not isinstance(value, dict) or not all(isinstance(k, str) for k in value):
        raise ValueError(f"must give a dict with string keys, got {text!r}")
    return value


# ----------------------------------------------------------------- hyper-parameter checks
#: RL Zoo keys the training script handles itself (the rest go to the algorithm's __init__)
ZOO_KEYS = frozenset(
    {"n_envs", "n_timesteps", "policy", "normalize", "env_kwargs", "noise_type", "noise_std"}
)
#: keys of this project's own (not RL Zoo's): a residual policy on an Eq. 32 baseline
#: (``agents.residual``)
RESIDUAL_KEYS = frozenset({"residual", "residual_scale"})
#: and one decision per excitation period in the design space of Eq. 32 (``agents.period``)
PERIOD_KEYS = frozenset({"period_actions"})
#: keywords of the algorithms' __init__ that the script sets (or that YAML cannot express)
_SET_BY_SCRIPT = {
    "env": "the env is built from --scene",
    "seed": "use --seed",
    "verbose": "set by the script",
    "device": "set by the script (cpu)",
    "tensorboard_log": "the run folder's tb/ is used",
    "_init_setup_model": "set by SB3",
    "action_noise": "use noise_type and noise_std",
    "rollout_buffer_class": "a Python class: not supported in the YAML",
    "replay_buffer_class": "a Python class: not supported in the YAML",
}
_INF = float("inf")
#: ranges (lo, hi, lo_open, hi_open) of the numbers; applied to a schedule's initial value too
RANGES = {
    "gamma": (0, 1, True, False),
    "gae_lambda": (0, 1, False, False),
    "learning_rate": (0, _INF, True, True),
    "clip_range": (0, _INF, True, True),
    "clip_range_vf": (0, _INF, True, True),
    "tau": (0, 1, True, False),
    "ent_coef": (0, _INF, False, True),
    "vf_coef": (0, _INF, False, True),
    "max_grad_norm": (0, _INF, True, True),
    "target_kl": (0, _INF, True, True),
    "target_policy_noise": (0, _INF, False, True),
    "target_noise_clip": (0, _INF, False, True),
    "noise_std": (0, _INF, False, True),
    "n_envs": (1, 4096, False, False),
    "n_timesteps": (1, 10**12, False, False),
    "n_steps": (1, _INF, False, True),
    "batch_size": (1, _INF, False, True),
    "n_epochs": (1, _INF, False, True),
    "buffer_size": (1, _INF, False, True),
    "learning_starts": (0, _INF, False, True),
    "gradient_steps": (-1, _INF, False, True),
    "policy_delay": (1, _INF, False, True),
    "target_update_interval": (1, _INF, False, True),
    "sde_sample_freq": (-1, _INF, False, True),
    "stats_window_size": (1, _INF, False, True),
    "train_freq": (1, _INF, False, True),
}
NOISE_TYPES = ("normal", "ornstein-uhlenbeck")


def _kinds(annotation) -> set:
    """The value kinds an SB3 annotation allows: int, float, bool, str, none, dict, tuple,
    schedule (a callable), class (a type)."""
    import collections.abc
    import types
    import typing

    origin = typing.get_origin(annotation)
    if origin in (typing.Union, types.UnionType):
        return set().union(*(_kinds(a) for a in typing.get_args(annotation)))
    if annotation is type(None) or annotation is None:
        return {"none"}
    for t, kind in ((bool, "bool"), (int, "int"), (float, "float"), (str, "str")):
        if annotation is t:
            return {kind}
    if annotation is dict or origin is dict:
        return {"dict"}
    if annotation is tuple or origin is tuple:
        return {"tuple"}
    if origin is type or annotation is type:
        return {"class"}
    if origin is collections.abc.Callable or annotation is collections.abc.Callable:
        return {"schedule"}
    return {"any"}


def _in_range(key, x):
    """``x`` (a number) in ``RANGES[key]`` (``validation.check_range``: NaN and inf refused
    too), or a ValueError naming the key and the range."""
    from rolling_env.validation import check_range

    lo, hi, lo_open, hi_open = RANGES.get(key, (-_INF, _INF, True, True))
    check_range(f"hyper-parameter {key!r}", x, lo, hi, lo_open=lo_open, hi_open=hi_open)
    return x


def _int(key, v):
    """An integer (a float with an integer value too, for ``1e6``), never truncated."""
    if (
        isinstance(v, bool)
        or not isinstance(v, (int, float))
        or (isinstance(v, float) and not (v == v and abs(v) != _INF and v == int(v)))
    ):
        raise ValueError(f"hyper-parameter {key!r} must be an integer, got {v!r}")
    return _in_range(key, int(v))


def _number(key, v):
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ValueError(f"hyper-parameter {key!r} must be a number, got {v!r}")
    return _in_range(key, float(v))


def check_value(key: str, v, kinds: set):  # noqa: C901 (one branch per annotated type SB3 uses)
    """``v`` checked against the kinds an SB3 keyword allows (and ``RANGES``), converted
    (an RL Zoo ``lin_<x>`` string to a linear schedule, a kwargs string to a dict)."""
    if v is None and "none" in kinds:
        return None
    if "any" in kinds:
        return v
    if "class" in kinds and not kinds - {"class", "none"}:
        raise ValueError(f"hyper-parameter {key!r} takes a Python class: not supported in the YAML")
    if "bool" in kinds:
        if not isinstance(v, bool):
            raise ValueError(f"hyper-parameter {key!r} must be true or false, got {v!r}")
        return v
    if "schedule" in kinds and isinstance(v, str):
        from stable_baselines3.common.utils import LinearSchedule

        head, _, tail = v.partition("_")
        try:
            x = float(tail) if head == "lin" else None
        except ValueError:
            x = None
        if x is None:
            raise ValueError(
                f"hyper-parameter {key!r} must be a number or 'lin_<number>' (RL "
                f"Zoo's linear schedule), got {v!r}"
            )
        return LinearSchedule(_in_range(key, x), 0.0, 1.0)  # x * progress_remaining
    if key == "ent_coef" and isinstance(v, str) and "str" in kinds:  # SAC: auto, auto_0.1
        head, _, tail = v.partition("_")
        try:
            ok = head == "auto" and (not tail or float(tail) > 0)
        except ValueError:
            ok = False
        if not ok:
            raise ValueError(
                f"hyper-parameter 'ent_coef' must be a number, 'auto' or "
                f"'auto_<initial value>', got {v!r}"
            )
        return v
    if key == "target_entropy" and isinstance(v, str):
        if v != "auto":
            raise ValueError(
                f"hyper-parameter 'target_entropy' must be a number or 'auto', got {v!r}"
            )
        return v
    if "tuple" in kinds and isinstance(v, (list, tuple)):
        if not (len(v) == 2 and v[1] in ("step", "episode")):
            raise ValueError(
                f"hyper-parameter {key!r} must be an integer or [n, 'step' | 'episode'], got {v!r}"
            )
        return (_int(key, v[0]), v[1])
    if "dict" in kinds:
        try:
            return parse_kwargs(v) or {}
        except ValueError as e:
            raise ValueError(f"hyper-parameter {key!r}: {e}") from None
    if "float" in kinds:
        return _number(key, v)
    if "int" in kinds:
        return _int(key, v)
    if "str" in kinds and isinstance(v, str):
        return v
    want = " or ".join(sorted(kinds - {"none"})) + (" or null" if "none" in kinds else "")
    raise ValueError(f"hyper-parameter {key!r} must be {want}, got {v!r}")


def _algo_class(algo: str):
    import stable_baselines3 as sb3

    return {"ppo": sb3.PPO, "sac": sb3.SAC, "td3": sb3.TD3}[algo]


def check_hyperparams(algo: str, hp: dict) -> dict:
    """Validate an entry of the hyper-parameter YAML for ``algo``: every key is either an RL
    Zoo key the script handles (``ZOO_KEYS``) or a keyword of the algorithm's ``__init__``
    (found with ``inspect.signature``), with a value of the type SB3 annotates and in
    ``RANGES``; anything else raises a ValueError naming the key (an integer may be a float
    with an integer value: ``1e3``, which ``rolling_env.env.scenes.read_yaml`` reads as a float),
    and the values inside ``policy_kwargs`` are checked too (``check_policy_kwargs``).  Returns
    ``{"n_envs", "n_timesteps", "policy", "normalize" (dict or None), "env_kwargs",
    "action_noise" (None or a (type, std) pair), "residual" (None or a (base, scale) pair),
    "period_actions" (bool),
    "kwargs" (for the algorithm)}``;
    ``n_timesteps`` is None when the entry has none."""
    import inspect

    cls = _algo_class(algo)
    params = inspect.signature(cls.__init__).parameters
    script = ZOO_KEYS | RESIDUAL_KEYS | PERIOD_KEYS
    unknown = sorted(k for k in hp if k not in script and k not in params or k == "self")
    if unknown:
        raise ValueError(
            f"unknown hyper-parameter(s) {', '.join(map(repr, unknown))} for "
            f"{cls.__name__} (keys: the RL Zoo keys {sorted(ZOO_KEYS)}, "
            f"{sorted(RESIDUAL_KEYS | PERIOD_KEYS)} and the keywords of "
            f"{cls.__name__}.__init__)"
        )
    out = {
        "n_envs": _int("n_envs", hp.get("n_envs", 1)),
        "n_timesteps": (_int("n_timesteps", hp["n_timesteps"]) if "n_timesteps" in hp else None),
    }
    policy = hp.get("policy", "MlpPolicy")
    if policy != "MlpPolicy":
        raise ValueError(
            f"hyper-parameter 'policy' must be 'MlpPolicy' (the observation is a "
            f"flat vector), got {policy!r}"
        )
    out["policy"] = policy
    out["normalize"] = _check_normalize(hp.get("normalize", False))
    env_kwargs = hp.get("env_kwargs") or {}
    if not isinstance(env_kwargs, dict):
        raise ValueError(f"hyper-parameter 'env_kwargs' must be a mapping, got {env_kwargs!r}")
    out["env_kwargs"] = dict(env_kwargs)
    out["action_noise"] = _check_action_noise(hp, cls.__name__, "action_noise" in params)
    out["residual"], out["period_actions"] = _check_residual_and_period(hp)
    out["kwargs"] = _algo_kwargs(
        algo, cls, params, {k: v for k, v in hp.items() if k not in script}
    )
    return out


def _check_normalize(value):
    """The ``normalize`` entry as VecNormalize's keywords (None: no normalisation)."""
    import inspect
    import numbers

    try:
        norm = parse_kwargs(value)
    except ValueError as e:
        raise ValueError(f"hyper-parameter 'normalize': {e}") from None
    if norm is None:
        return None
    from stable_baselines3.common.vec_env import VecNormalize

    allowed = set(inspect.signature(VecNormalize.__init__).parameters) - {
        "self",
        "venv",
        "training",
        "gamma",
        "norm_obs_keys",
    }
    bad = sorted(set(norm) - allowed)
    if bad:
        raise ValueError(
            f"hyper-parameter 'normalize': unknown key(s) {bad} (VecNormalize "
            f"takes {sorted(allowed)}; gamma is the algorithm's)"
        )
    for k, x in list(norm.items()):
        if k in ("norm_obs", "norm_reward") and not isinstance(x, bool):
            raise ValueError(f"hyper-parameter 'normalize': {k} must be true or false, got {x!r}")
        if k in ("clip_obs", "clip_reward", "epsilon") and (
            isinstance(x, bool) or not isinstance(x, numbers.Real) or not x > 0
        ):
            raise ValueError(f"hyper-parameter 'normalize': {k} must be a number > 0, got {x!r}")
    return norm


def _check_action_noise(hp, algo_name, takes_noise):
    """``noise_type`` / ``noise_std`` as a (type, std) pair, or None when neither is set."""
    noise_type, noise_std = hp.get("noise_type"), hp.get("noise_std")
    if noise_type is None and noise_std is None:
        return None
    if not takes_noise:
        raise ValueError(
            f"hyper-parameter 'noise_type' / 'noise_std': {algo_name} takes no action noise"
        )
    if noise_type not in NOISE_TYPES:
        raise ValueError(
            f"hyper-parameter 'noise_type' must be one of {NOISE_TYPES} (with "
            f"noise_std), got {noise_type!r}"
        )
    if noise_std is None:
        raise ValueError("hyper-parameter 'noise_std' is required with noise_type")
    return (noise_type, _number("noise_std", noise_std))


def _check_residual_and_period(hp):
    """The ``residual`` (None or a (base, scale) pair) and ``period_actions`` (bool) entries,
    which exclude each other."""
    residual = None
    if hp.get("residual") is not None:
        from .residual import SCALE_DEFAULT, check_residual

        try:
            residual = check_residual(hp["residual"], hp.get("residual_scale", SCALE_DEFAULT))
        except ValueError as e:
            raise ValueError(f"hyper-parameter {e}") from None
    elif hp.get("residual_scale") is not None:
        raise ValueError(
            "hyper-parameter 'residual_scale' needs 'residual' (the baseline the "
            "policy's actions are added to)"
        )
    from .period import check_period_actions

    try:
        period = check_period_actions(hp.get("period_actions", False))
    except ValueError as e:
        raise ValueError(f"hyper-parameter {e}") from None
    if period and residual is not None:
        raise ValueError(
            "hyper-parameters 'period_actions' and 'residual' exclude each other (a period "
            "action is a working point, not a correction of a tick's action)"
        )
    return residual, period


def _algo_kwargs(algo, cls, params, entries):
    """The keywords for the algorithm class ``cls`` (``params``: its ``__init__``'s) from the
    entries that are not the script's, each checked against its annotation."""
    import inspect

    kwargs = {}
    for k, v in entries.items():
        if k in _SET_BY_SCRIPT:
            raise ValueError(
                f"hyper-parameter {k!r} cannot be set in the YAML: {_SET_BY_SCRIPT[k]}"
            )
        kwargs[k] = check_value(k, v, _kinds(params[k].annotation))
    if "policy_kwargs" in kwargs:
        pol = cls.policy_aliases["MlpPolicy"]
        allowed = set(inspect.signature(pol.__init__).parameters) - {
            "self",
            "observation_space",
            "action_space",
            "lr_schedule",
            "use_sde",
        }
        bad = sorted(set(kwargs["policy_kwargs"]) - allowed)
        if bad:
            raise ValueError(
                f"hyper-parameter 'policy_kwargs': unknown key(s) {bad} for "
                f"{pol.__name__} (allowed: {sorted(allowed)})"
            )
        kwargs["policy_kwargs"] = check_policy_kwargs(algo, kwargs["policy_kwargs"])
    return kwargs


# ----------------------------------------------------------------- policy_kwargs
NET_WIDTH_MAX = 1024  # units per hidden layer (the observation has 13 numbers, the action 3)
NET_DEPTH_MAX = 8  # hidden layers per network
N_CRITICS_MAX = 10
#: torch.nn.modules.activation classes that are no element-wise activation or need arguments
_NOT_ACTIVATIONS = frozenset(
    {"MultiheadAttention", "GLU", "Threshold", "Softmax", "Softmax2d", "Softmin", "LogSoftmax"}
)


def activation_classes() -> dict:
    """The activations ``policy_kwargs.activation_fn`` may name: the element-wise activation
    classes of ``torch.nn`` (``torch.nn.modules.activation``, less ``_NOT_ACTIVATIONS``:
    attention, GLU (halves its input), the softmax family (across units) and Threshold
    (needs arguments))."""
    import torch

    mod = torch.nn.modules.activation
    return {
        n: c
        for n, c in vars(mod).items()
        if isinstance(c, type)
        and issubclass(c, torch.nn.Module)
        and c.__module__ == mod.__name__
        and n not in _NOT_ACTIVATIONS
    }


def _layers(name: str, v) -> list:
    ok = (
        isinstance(v, (list, tuple))
        and len(v) <= NET_DEPTH_MAX
        and all(
            isinstance(w, int) and not isinstance(w, bool) and 1 <= w <= NET_WIDTH_MAX for w in v
        )
    )
    if not ok:
        raise ValueError(
            f"hyper-parameter 'policy_kwargs': {name} must be a list of at most "
            f"{NET_DEPTH_MAX} hidden-layer widths, each an integer in [1, "
            f"{NET_WIDTH_MAX}], got {v!r}"
        )
    return list(v)


def check_policy_kwargs(algo: str, pk: dict) -> dict:  # noqa: C901 (one check per policy keyword)
    """The values of ``policy_kwargs`` for the algorithm's MlpPolicy (keys are checked by
    ``check_hyperparams``): ``net_arch`` a list of hidden-layer widths (``_layers``) or a dict
    of them with keys pi and vf (PPO) or pi and qf (SAC, TD3); ``activation_fn`` one of
    ``activation_classes``; ``log_std_init`` in [LOG_STD_MIN, LOG_STD_MAX] = [-20, 2] (SB3's
    clamp of SAC's log std; exp(1e308) made the first PPO update NaN); ``clip_mean`` in
    (0, 100]; ``n_critics`` in [1, N_CRITICS_MAX]; ``ortho_init``, ``full_std``,
    ``use_expln``, ``squash_output``, ``share_features_extractor``, ``normalize_images``
    true or false; ``optimizer_class`` a torch.optim optimizer; ``optimizer_kwargs`` and
    ``features_extractor_kwargs`` mappings; ``features_extractor_class`` not at all (the
    YAML can name no SB3 class).  A ValueError naming policy_kwargs and the key otherwise.
    What the values do together (e.g. an optimizer keyword) is checked by building the
    policy (``check_policy``)."""
    import torch
    from stable_baselines3.sac.policies import LOG_STD_MAX, LOG_STD_MIN

    from rolling_env.validation import check_int, check_range

    heads = ("pi", "vf") if algo == "ppo" else ("pi", "qf")
    out = dict(pk)
    for k, v in pk.items():
        name = f"hyper-parameter 'policy_kwargs': {k}"
        if k == "net_arch":
            if isinstance(v, dict):
                bad = sorted(set(v) - set(heads), key=str)
                if bad:
                    raise ValueError(
                        f"{name} as a dict takes the keys {' and '.join(heads)} "
                        f"(for {algo.upper()}), got {bad}"
                    )
                out[k] = {h: _layers(f"net_arch[{h!r}]", x) for h, x in v.items()}
            elif v is not None:
                out[k] = _layers("net_arch", v)
        elif k == "activation_fn":
            allowed = activation_classes()
            if not (isinstance(v, type) and allowed.get(v.__name__) is v):
                raise ValueError(
                    f"{name} must be a torch.nn activation class ("
                    f"{', '.join('nn.' + n for n in sorted(allowed))}), got "
                    f"{getattr(v, '__name__', v)!r}"
                )
        elif k == "log_std_init":
            out[k] = check_range(name, v, LOG_STD_MIN, LOG_STD_MAX)
        elif k == "clip_mean":
            out[k] = check_range(name, v, 0.0, 100.0, lo_open=True)
        elif k == "n_critics":
            out[k] = check_int(name, v, 1, N_CRITICS_MAX)
        elif k in (
            "ortho_init",
            "full_std",
            "use_expln",
            "squash_output",
            "share_features_extractor",
            "normalize_images",
        ):
            if not isinstance(v, bool):
                raise ValueError(f"{name} must be true or false, got {v!r}")
        elif k == "optimizer_class":
            if not (isinstance(v, type) and issubclass(v, torch.optim.Optimizer)):
                raise ValueError(
                    f"{name} must be a torch.optim optimizer class such as "
                    f"th.optim.Adam, got {getattr(v, '__name__', v)!r}"
                )
        elif k in ("optimizer_kwargs", "features_extractor_kwargs"):
            if v is not None and not (isinstance(v, dict) and all(isinstance(x, str) for x in v)):
                raise ValueError(f"{name} must be a mapping of keywords, got {v!r}")
        elif k == "features_extractor_class":
            raise ValueError(
                f"{name} takes an SB3 features extractor class: not supported in "
                "the YAML (the default FlattenExtractor fits the flat observation)"
            )
    return out


def check_policy(algo: str, kwargs: dict, env) -> None:
    """Build the algorithm's MlpPolicy once on ``env``'s spaces with the checked
    ``kwargs["policy_kwargs"]`` (and ``use_sde``, as the algorithm passes it): an error while
    building it (a RuntimeError from torch, a TypeError or ValueError from the optimizer
    keywords, ...) is a one-line ValueError naming policy_kwargs, before any run folder."""
    import inspect

    pol = _algo_class(algo).policy_aliases["MlpPolicy"]
    pk = dict(kwargs.get("policy_kwargs") or {})
    if "use_sde" in inspect.signature(pol.__init__).parameters:
        pk["use_sde"] = bool(kwargs.get("use_sde", False))
    try:
        pol(env.observation_space, env.action_space, lambda _: 1e-3, **pk)
    except Exception as e:  # noqa: BLE001  (whatever SB3 or torch raise: one line, named)
        raise ValueError(
            f"hyper-parameter 'policy_kwargs': {pol.__name__} cannot be built "
            f"with {kwargs.get('policy_kwargs')!r}: {one_line(e)}"
        ) from None


def action_noise(spec, n_actions: int = 3):
    """SB3 action noise from ``check_hyperparams``' ``(type, std)`` pair (None: none)."""
    if spec is None:
        return None
    import numpy as np
    from stable_baselines3.common.noise import NormalActionNoise, OrnsteinUhlenbeckActionNoise

    kind, std = spec
    cls = NormalActionNoise if kind == "normal" else OrnsteinUhlenbeckActionNoise
    return cls(np.zeros(n_actions), std * np.ones(n_actions))
