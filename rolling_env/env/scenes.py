"""Scenes: YAML files in ``configs/scenes/`` that fix the physics and the task of RollingDrive-v0.

Every key is required (a scene is a complete, explicit description), values in SI units.
Unknown keys, missing keys, wrong types and out-of-range values are rejected with a message
that names the key and its allowed range; keyword overrides (``gym.make(..., mu=0.1)``)
follow the same checks.  ``.inf`` (YAML) or the string ``"inf"`` means infinity where allowed.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from rolling_env.paths import SCENE_DIR  # noqa: F401  (re-exported: the shipped scenes)
from rolling_env.physics.ranges import PHYSICAL_RANGES
from rolling_env.validation import check_range

_INF = math.inf
DEFAULT_ACCURACY = 0.01  # a scene's ``accuracy`` where its file leaves it out
DEFAULT_GRID_LEVELS = 4  # a scene's ``grid_levels`` where its file leaves it out


@dataclass(frozen=True)
class Scene:
    """A complete scene (all SI).  See ``configs/scenes/default.yaml`` for a commented example."""

    name: str
    description: str
    # contact physics
    R: float  # sphere radius [m]
    E_star: float  # effective Young modulus [Pa]
    G_star: float  # effective shear modulus [Pa]
    mu: float  # Coulomb friction coefficient [-] (inf: no slip)
    runner_mass: float  # [kg] (0: massless runner)
    F_ext: float  # constant load on the runner [N] (positive along +x)
    # actuators
    N_min: float  # smallest normal force the action can ask for [N]
    N_max: float  # largest normal force [N]
    omega_R_max: float  # largest rolling rate |omega R| [m/s]
    creep_max: float  # largest |1 - v/(omega R)| the action can ask for [-]
    stroke_roll: float  # rolling travel limit: |integral omega R dt| <= stroke_roll [m]
    stroke_translate: float  # translation travel limit: |integral v dt| <= stroke_translate [m]
    # numerics and timing
    period: float  # nominal excitation period tau [s] (time scale of the task)
    ticks_per_period: int  # control ticks per nominal period
    sub_steps: int | str  # physics sub-steps per control tick, or "auto" (``n_sub``)
    resolution: float  # cells per contact radius at N_max
    # task
    episode_steps: int  # control ticks per episode (the env truncates there)
    target_min: float  # smallest |target displacement| sampled at reset [m]
    target_max: float  # largest |target displacement| [m]
    target_both_signs: bool  # sample the target's sign too
    tolerance: float  # |error| counted as "at the target" [m]
    w_track: float  # weight of the tracking term (per tick, on |error|/target_max)
    w_wear: float  # weight of the wear term (per tick, on slip work / wear_ref)
    accuracy: float = DEFAULT_ACCURACY  # relative error "auto" sub-steps aim at [-]
    grid_levels: int = DEFAULT_GRID_LEVELS  # times the cells may halve for a smaller contact
    w_final: float = 0.0  # weight of the terminal term (last tick, on |error|/tolerance)
    # physics drawn per episode: ((key, low, high), ...) of RANDOMIZABLE keys (single envs)
    randomize: tuple = ()

    @property
    def dt(self) -> float:
        """Control tick [s]."""
        return self.period / self.ticks_per_period

    @property
    def n_sub(self) -> int:
        """Sub-steps per tick: ``sub_steps`` where it is a number, else ``auto_sub_steps``."""
        return self.sub_steps if isinstance(self.sub_steps, int) else auto_sub_steps(self)

    def replace(self, **overrides) -> "Scene":
        return validate(dataclasses.replace(self, **_coerce_all(overrides)))


EPISODE_STEPS_MAX = 10**8
# "auto" sub-steps (``auto_sub_steps``): the episode's slip work and runner displacement are
# off by at most about C_TRAVEL x (cells the patch crosses per sub-step)^2 with finite
# friction (the trailing edge's cells, each charged from the onset of its sliding),
# C_TRAVEL_STICK x that with infinite friction (counting cells of at least a_max /
# STICK_CELLS), and by about C_RUNNER x (omega_n dt)^2 for a
# free runner (omega_n on the stuck contact at N_max).  Upper bounds measured on the shipped
# scenes' episodes (bang-bang actions, which reverse the rolling at full rate and change the
# load every tick, set C_TRAVEL) and their held-out variants (light_stiff's runner at half
# its mass sets C_RUNNER) against refined runs (docs/numerics.md).
C_TRAVEL = 0.02
C_TRAVEL_STICK = 0.002
# With infinite friction the patch travel counts cells of at least a_max / STICK_CELLS: the
# walk is exact and no slip work is charged, so cells finer than that need no shorter
# sub-steps (measured: heavy_inf_friction at 128 and 256 cells per radius ends its episodes
# as far off at the sub-steps of 64 cells as at twice them).
STICK_CELLS = 64
C_RUNNER = 1.0
AUTO_SUB_STEPS_MAX = 4096

_SPEC = {  # key: (type, lo, hi, lo_open, allow_inf): a scene either builds or is rejected
    # here, never NaN or a crash later
    **PHYSICAL_RANGES,
    "ticks_per_period": (int, 2, 10000, False, False),
    "sub_steps": (int, 1, 100000, False, False),
    "resolution": (float, 1.0, 4096.0, False, False),
    "episode_steps": (int, 1, EPISODE_STEPS_MAX, False, False),
    "target_min": (float, 0.0, 1.0, False, False),
    "target_max": (float, 1e-15, 1.0, False, False),
    "target_both_signs": (bool, None, None, False, False),
    "tolerance": (float, 1e-15, 1.0, False, False),
    "w_track": (float, 0.0, 1e6, False, False),
    "w_wear": (float, 0.0, 1e12, False, False),
    "accuracy": (float, 1e-6, 0.5, False, False),
    "grid_levels": (int, 0, 12, False, False),
    "w_final": (float, 0.0, 1e6, False, False),
}
#: keys a scene file may leave out (their defaults above)
_OPTIONAL = {"accuracy", "grid_levels", "w_final", "randomize"}
#: keys a scene may draw per episode (``randomize``); mu and runner_mass log-uniformly (they
#: scale), F_ext uniformly
RANDOMIZABLE = ("mu", "runner_mass", "F_ext")
LOG_UNIFORM = ("mu", "runner_mass")
E_OVER_G_RANGE = (0.01, 100.0)  # E*/G*: about 1-2 for real materials (isotropic, 0 <= nu <= 0.5)

_FIELDS = [f.name for f in dataclasses.fields(Scene)]


def _coerce(key, value):
    if key in ("name", "description"):
        if not isinstance(value, str):
            raise ValueError(f"scene key '{key}' must be a string, got {type(value).__name__}")
        if key == "name" and (
            not value
            or value.startswith(".")
            or len(value) > 100
            or any(ch in value for ch in "/\\\0")
        ):
            # output files are named after the scene: it must stay one file name
            raise ValueError(
                "scene key 'name' must be a file name: 1 to 100 characters, no "
                f"'/', '\\' or NUL, not starting with '.', got {value!r}"
            )
        return value
    if key == "randomize":
        return _coerce_randomize(value)
    if key not in _SPEC:
        raise ValueError(f"unknown scene key '{key}'; allowed keys: {', '.join(_FIELDS)}")
    if key == "sub_steps":
        if isinstance(value, str) and value.strip().lower() == "auto":
            return "auto"
        try:
            return _coerce_number(key, value)
        except ValueError as e:
            raise ValueError(f"{e} (or 'auto': chosen from the scene's accuracy)") from None
    return _coerce_number(key, value)


def _coerce_number(key, value):
    typ, lo, hi, lo_open, allow_inf = _SPEC[key]
    if typ is bool:
        if not isinstance(value, (bool, np.bool_)):
            raise ValueError(f"scene key '{key}' must be true or false, got {value!r}")
        return bool(value)
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "fiu":
        value = value.item()  # a 0-d array, as reset options accept it
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, (numbers.Real, str)):
        raise ValueError(f"scene key '{key}' must be a number, got {value!r}")  # numpy scalars ok
    if isinstance(value, str):
        if value.strip().lower() in ("inf", ".inf", "infinity") and allow_inf:
            value = _INF
        else:
            try:
                value = float(value)
            except ValueError:
                raise ValueError(f"scene key '{key}' must be a number, got {value!r}") from None
    if typ is int:
        if isinstance(value, numbers.Integral) and not lo <= value <= hi:  # no float(): 10**400
            shown = value if abs(value) < 10**18 else f"an integer of {len(str(abs(value)))} digits"
            raise ValueError(f"scene key '{key}' must be an integer in [{lo}, {hi}], got {shown}")
        fv = float(value)
        if not math.isfinite(fv) or fv != int(fv):
            raise ValueError(f"scene key '{key}' must be an integer in [{lo}, {hi}], got {value!r}")
        value = int(value)
        if not lo <= value <= hi:
            raise ValueError(f"scene key '{key}' must be an integer in [{lo}, {hi}], got {value}")
    x = check_range(f"scene key '{key}'", value, lo, hi, lo_open=lo_open, allow_inf=allow_inf)
    return typ(x) if typ is int else x


def _coerce_randomize(value) -> tuple:
    """``randomize`` as a sorted tuple of (key, low, high): from a mapping ``{key: [low,
    high]}`` (a scene file) or from such triples (a Scene's own value)."""
    if value is None:
        return ()
    if isinstance(value, dict):
        items = list(value.items())
    elif isinstance(value, (list, tuple)) and all(
        isinstance(t, (list, tuple)) and len(t) == 3 for t in value
    ):
        items = [(t[0], (t[1], t[2])) for t in value]
    else:
        raise ValueError(
            "scene key 'randomize' must be a mapping of key: [low, high] with "
            f"keys among {', '.join(RANDOMIZABLE)}, got {value!r}"
        )
    out = []
    for k, r in items:
        if k not in RANDOMIZABLE:
            raise ValueError(
                f"scene key 'randomize': {k!r} cannot be drawn per episode (one "
                f"of {', '.join(RANDOMIZABLE)})"
            )
        if not isinstance(r, (list, tuple)) or len(r) != 2:
            raise ValueError(f"scene key 'randomize.{k}' must be [low, high], got {r!r}")
        try:
            lo, hi = (_coerce_number(k, x) for x in r)
        except ValueError as e:
            raise ValueError(f"scene key 'randomize.{k}': {e}") from None
        if not (math.isfinite(lo) and math.isfinite(hi)) or lo > hi:
            raise ValueError(
                f"scene key 'randomize.{k}' must be finite [low, high] with low "
                f"<= high, got [{lo:g}, {hi:g}]"
            )
        if k in LOG_UNIFORM and lo <= 0.0:
            raise ValueError(
                f"scene key 'randomize.{k}' is drawn log-uniformly: low must be > 0, got {lo:g}"
            )
        out.append((k, lo, hi))
    return tuple(sorted(out))


def draw_physics(scene: "Scene", rng) -> dict:
    """One episode's draw of the scene's ``randomize`` keys with ``rng`` (a numpy Generator):
    log-uniform for ``LOG_UNIFORM`` keys, uniform otherwise."""
    out = {}
    for k, lo, hi in scene.randomize:
        if k in LOG_UNIFORM:
            x = math.exp(rng.uniform(math.log(lo), math.log(hi)))
        else:
            x = rng.uniform(lo, hi)
        out[k] = float(min(max(x, lo), hi))
    return out


def episode_scene(scene: "Scene", draw: dict) -> "Scene":
    """The scene of one episode of a randomised scene: its draw in place of the nominal
    values (every draw within the ranges is valid: ``validate`` checks the corners)."""
    return dataclasses.replace(scene, randomize=(), **draw)


def contact_radius_max(s: "Scene") -> float:
    """Hertz contact radius at N_max [m]."""
    return math.sqrt(s.R * (3 * s.N_max / (4 * s.E_star * math.sqrt(s.R))) ** (2 / 3))


def auto_sub_steps(s: "Scene") -> int:
    """Sub-steps per tick for a relative error of about ``accuracy`` in the episode's slip
    work and runner displacement, from the two things the step must resolve (both second
    order in it; constants measured, module header):

    * the patch travel: ``omega_R_max dt / dx`` cells per tick at full rolling speed, each
      sub-step crossing at most sqrt(accuracy / C_TRAVEL) cells (finite friction; the slip
      work's trailing edge) or sqrt(accuracy / C_TRAVEL_STICK) cells of at least
      a_max / STICK_CELLS (infinite friction);
    * a free runner's ringing on the stuck contact: ``omega_n dt`` radians per tick with
      omega_n = sqrt(2 a_max G* / m), each sub-step at most sqrt(accuracy / C_RUNNER) rad.
      A heavy runner needs few, a light one many; a massless or prescribed one none.

    At least 1, at most ``AUTO_SUB_STEPS_MAX``."""
    a_max = contact_radius_max(s)
    finite = math.isfinite(s.mu)
    per_radius = s.resolution if finite else min(s.resolution, STICK_CELLS)
    cells = s.omega_R_max * s.dt / (a_max / per_radius)
    n = cells * math.sqrt((C_TRAVEL if finite else C_TRAVEL_STICK) / s.accuracy)
    if 0.0 < s.runner_mass:
        omega_n = math.sqrt(2.0 * a_max * s.G_star / s.runner_mass)
        n = max(n, omega_n * s.dt * math.sqrt(C_RUNNER / s.accuracy))
    return int(min(max(math.ceil(n - 1e-9), 1), AUTO_SUB_STEPS_MAX))


def _coerce_all(d: dict) -> dict:
    return {k: _coerce(k, v) for k, v in d.items()}


def validate(scene: Scene) -> Scene:
    """Cross-key checks (single keys are checked on construction)."""
    s = scene
    if s.N_min >= s.N_max:
        raise ValueError(f"scene key 'N_min' must be < N_max = {s.N_max}, got {s.N_min}")
    if s.target_min > s.target_max:
        raise ValueError(
            f"scene key 'target_min' must be <= target_max = {s.target_max}, got {s.target_min}"
        )
    lo, hi = E_OVER_G_RANGE
    if not lo <= s.E_star / s.G_star <= hi:
        raise ValueError(
            f"scene keys 'E_star' and 'G_star' must have a ratio E_star/G_star in "
            f"[{lo:g}, {hi:g}], got {s.E_star / s.G_star:.3g}"
        )
    # the least force the contact holds; no contact (N_min = 0) holds none, also with mu = inf
    hold = s.mu * s.N_min if s.N_min > 0.0 else 0.0
    if s.runner_mass == 0.0 and s.F_ext != 0.0 and not abs(s.F_ext) < hold:
        # a massless runner under load is in equilibrium only while the contact holds the load
        # (|F_ext| <= mu N); the env kernel does not report the sliding case (it would step on
        # with a meaningless velocity), so a scene must exclude it for every action: the least
        # force the contact can hold is mu N_min
        raise ValueError(
            f"scene key 'F_ext' must satisfy |F_ext| < mu N_min = "
            f"{hold:.6g} N when runner_mass is 0, got {s.F_ext:g} N (a "
            "loaded massless runner has no force equilibrium once the contact "
            "slides, and the env cannot report that case): give the runner a "
            "mass > 0, raise N_min or mu, or lower |F_ext|"
        )
    if s.randomize:
        import itertools

        for k, lo, hi in s.randomize:
            nominal = getattr(s, k)
            if not lo <= nominal <= hi:
                raise ValueError(
                    f"scene key '{k}' = {nominal:g} (the nominal value the "
                    f"baselines design for) must lie in its randomize range "
                    f"[{lo:g}, {hi:g}]"
                )
        keys = [k for k, _, _ in s.randomize]
        for corner in itertools.product(*[(lo, hi) for _, lo, hi in s.randomize]):
            draw = dict(zip(keys, corner))
            try:
                validate(episode_scene(s, draw))
            except ValueError as e:
                raise ValueError(
                    f"scene key 'randomize': the draw {draw} gives an invalid scene: {e}"
                ) from None
    a_max = contact_radius_max(s)
    if a_max > 0.5 * s.R:
        raise ValueError(
            f"scene keys 'N_max', 'E_star' and 'R' give a contact radius "
            f"{a_max:.3g} m > R/2 = {0.5 * s.R:.3g} m at N_max: outside the "
            "small-strain contact theory (lower N_max or raise E_star or R)"
        )
    return s


def load_scene(scene: str | os.PathLike | dict | Scene = "default", **overrides) -> Scene:
    """Load a scene by name (``configs/scenes/<name>.yaml``), path, dict or Scene, then apply
    keyword overrides.  Every field is required in the file."""
    if isinstance(scene, Scene):  # checked again: a Scene can be built or replaced unchecked
        scene = dataclasses.asdict(scene)
    if not isinstance(scene, (str, os.PathLike, dict)):
        raise ValueError(
            f"scene must be a shipped scene name ({', '.join(list_scenes())}), a "
            f"path to a YAML file, a dict or a Scene, got {scene!r}"
        )
    if isinstance(scene, dict):
        raw = dict(scene)
        src = "<dict>"
    else:
        path = Path(scene)
        if path.suffix.lower() not in (".yaml", ".yml"):
            path = SCENE_DIR / f"{scene}.yaml"
            if not path.exists():
                raise ValueError(
                    f"unknown scene {scene!r}; shipped scenes: "
                    f"{', '.join(list_scenes())} (or give a path to a .yaml file)"
                )
        if not path.exists():
            raise ValueError(f"scene file {str(path)!r} does not exist")
        raw = read_yaml(path)
        if not isinstance(raw, dict):
            raise ValueError(f"scene file {str(path)!r} must hold a mapping of keys to values")
        raw.setdefault("name", path.stem)
        src = str(path)
    missing = [k for k in _FIELDS if k not in raw and k not in _OPTIONAL]
    if missing:
        raise ValueError(f"scene {src} is missing key(s): {', '.join(missing)}")
    vals = _coerce_all(raw)
    vals.update(_coerce_all(overrides))
    return validate(Scene(**vals))


class _UniqueKeyLoader(yaml.SafeLoader):
    """YAML's safe loader, except that a key given twice in one mapping is an error (plain
    YAML keeps the last value silently, hiding an edit that did not take), and that numbers
    in exponent form without a dot or a signed exponent (``3e-4`` has one, ``1e3`` neither)
    are floats, as in YAML 1.2 (PyYAML's YAML 1.1 reads ``1e3`` and ``5e-7`` as strings)."""

    def construct_mapping(self, node, deep=False):
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue  # merged keys may be overridden, as with safe_load
                key = self.construct_object(key_node, deep=deep)
                try:
                    dup = key in seen
                except TypeError:  # an unhashable key: the base class reports it
                    continue
                if dup:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"duplicate key {key!r}", key_node.start_mark
                    )
                seen.add(key)
        return super().construct_mapping(node, deep=deep)


_UniqueKeyLoader.add_implicit_resolver(  # copied per class by PyYAML: SafeLoader is unchanged
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


#: held-out variants of a scene: one physics key scaled by each factor (where finite and
#: nonzero), the physics no controller was designed or trained for
VARIANT_FACTORS = {"mu": (0.5, 2.0), "runner_mass": (0.5, 2.0), "F_ext": (0.5, 1.5)}


def variants(scene) -> list[tuple[str, dict]]:
    """(label, overrides) of the held-out variants of ``scene`` (``VARIANT_FACTORS``): the
    friction coefficient where finite, the runner's mass, the load where there is one; the
    label names the key and its factor (``"mu x2"``)."""
    sc = load_scene(scene)
    out = []
    for key, factors in VARIANT_FACTORS.items():
        x = getattr(sc, key)
        if not math.isfinite(x) or x == 0:
            continue
        for f in factors:
            out.append((f"{key} x{f:g}", {key: x * f}))
    return out


def read_yaml(path, what: str = "scene file"):
    """The YAML document in ``path``; a syntax error, a duplicate key (``_UniqueKeyLoader``),
    text that is not UTF-8 or a file that cannot be read is a one-line ValueError naming
    ``what`` and the file (and the line, for YAML errors).  Scene files, the hyper-parameter
    files and run configs of ``agents`` are read with it."""
    try:
        with open(path, encoding="utf-8") as f:
            return yaml.load(f, Loader=_UniqueKeyLoader)
    except yaml.YAMLError as e:
        msg = " ".join(str(e).split())
        raise ValueError(f"{what} {str(path)!r} is not valid YAML: {msg}") from None
    except UnicodeDecodeError as e:
        raise ValueError(
            f"{what} {str(path)!r} is not UTF-8 text (byte {e.start}: {e.reason})"
        ) from None
    except OSError as e:  # a folder, no permission, ...
        raise ValueError(
            f"{what} {str(path)!r} cannot be read: {e.strerror or e.__class__.__name__}"
        ) from None


def list_scenes() -> list[str]:
    return sorted(p.stem for p in SCENE_DIR.glob("*.yaml"))


# ------------------------------------------------------- what a scene is, as runs record it


def scene_fields(scene) -> dict:
    """What a run was trained on: the checked Scene's fields (``load_scene``) except its name
    and description, which change nothing in the env, plus ``n_sub``, the sub-steps per tick
    the env takes (``sub_steps: auto`` alone does not say how many: that depends on the
    scene's ``accuracy`` and on the rule of ``auto_sub_steps``)."""
    sc = scene if isinstance(scene, Scene) else load_scene(scene)
    fields = {k: v for k, v in dataclasses.asdict(sc).items() if k not in ("name", "description")}
    fields["randomize"] = [list(t) for t in sc.randomize]  # as YAML and JSON read it back
    fields["n_sub"] = int(sc.n_sub)
    return fields


def fields_digest(fields: dict) -> str:
    """SHA-256 (hex) of a ``scene_fields`` mapping (keys sorted, floats as repr: exact)."""
    import hashlib
    import json

    return hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()


def scene_digest(scene) -> str:
    """SHA-256 (hex) of ``scene_fields``: equal digests, equal physics, task and numerics."""
    return fields_digest(scene_fields(scene))


def scene_key(scene) -> str:
    """Key of a scene: in the hyper-parameter YAML, the run folders (``runs/<key>/``) and the
    results tables.  A shipped scene's name; for a scene file, its stem, except where the
    stem names a shipped scene whose content differs: then ``<stem>-<first 8 hex digits of
    scene_digest>`` (a custom default.yaml with mu 0.01 is not ``default``).  A file that
    cannot be read keeps its stem (loading it reports the error)."""
    p = Path(scene)
    if p.suffix.lower() not in (".yaml", ".yml"):
        return str(scene)
    stem = p.stem
    if stem in list_scenes():
        try:
            own = scene_digest(p)
        except (ValueError, OSError):
            return stem
        if own != scene_digest(stem):
            return f"{stem}-{own[:8]}"
    return stem
