"""Checked public wrapper around the MDR kernel: parameters, grid, state and stepping in SI units.

``DriveParams`` is the frozen physics (what a scene fixes), ``Drive`` owns one spring row and its
state and advances it tick by tick with piecewise-constant inputs (normal force or indentation,
omega R and v).  The compiled kernel is chosen once, from the feature set of the parameters
(finite or infinite friction, prescribed or free runner, load or none), see ``_kernel``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rolling_env.physics import _kernel as K
from rolling_env.physics.analytic import hertz_force, hertz_indentation
from rolling_env.physics.kernel_state import CellViews, check_flags
from rolling_env.validation import as_real_array, check_int, check_range

_INF = math.inf


@dataclass(frozen=True)
class DriveParams:
    """Physics of one drive, SI units.

    R        sphere radius [m]
    E_star   effective Young modulus E* [Pa]
    G_star   effective shear modulus G* [Pa]
    mu       Coulomb friction coefficient [-]; ``inf`` = no slip checks at all
    m        runner mass [kg]; ``inf`` = prescribed runner velocity, ``0`` = massless runner
             (force equilibrium T + F_ext = 0 at every instant)
    F_ext    constant external force on the runner [N] (positive along v*); needs m < inf.
             With m = 0 it must stay within what the contact holds (|F_ext| <= mu N, and no
             lift-off): where it does not, no equilibrium exists and ``Drive.run`` raises.
    """

    R: float
    E_star: float
    G_star: float
    mu: float = _INF
    m: float = _INF
    F_ext: float = 0.0

    def __post_init__(self):
        checked = {
            "R": check_range("R", self.R, 0.0, _INF, lo_open=True, hi_open=True),
            "E_star": check_range("E_star", self.E_star, 0.0, _INF, lo_open=True, hi_open=True),
            "G_star": check_range("G_star", self.G_star, 0.0, _INF, lo_open=True, hi_open=True),
            "mu": check_range("mu", self.mu, 0.0, _INF, allow_inf=True),
            "m": check_range("m", self.m, 0.0, _INF, allow_inf=True),
            "F_ext": check_range("F_ext", self.F_ext, -_INF, _INF, lo_open=True, hi_open=True),
        }
        for name, value in checked.items():  # store the checked floats (not "1e-3" strings)
            object.__setattr__(self, name, value)
        if math.isinf(self.m) and self.F_ext != 0.0:
            raise ValueError(
                "F_ext needs a finite runner mass m (a prescribed runner ignores loads)"
            )

    @property
    def features(self) -> tuple[bool, bool, bool]:
        """(finite friction, free runner, load): the structural choices of the kernel."""
        return (math.isfinite(self.mu), math.isfinite(self.m), self.F_ext != 0.0)


@dataclass
class Grid:
    """Spring row covering the patch-centre stroke [c_min, c_max] for half-widths up to a_max
    [m]."""

    c_min: float
    c_max: float
    a_max: float
    dx: float
    offset: float = 0.0  # shift of the cells by this fraction of dx (grid-alignment studies)
    x_lo: float = field(init=False)
    n: int = field(init=False)

    def __post_init__(self):
        check_range("dx", self.dx, 0.0, _INF, lo_open=True, hi_open=True)
        if not (self.c_max >= self.c_min):
            raise ValueError(
                f"stroke must satisfy c_min <= c_max, got [{self.c_min}, {self.c_max}]"
            )
        # a whole number of cells, centred on the stroke: mirrored strokes give mirrored grids
        width = self.c_max - self.c_min + 2.0 * (self.a_max + 2.0 * self.dx)
        self.n = int(math.ceil(width / self.dx))
        self.n += 1 if self.offset else 0
        self.x_lo = 0.5 * (self.c_min + self.c_max) - 0.5 * self.n * self.dx + self.offset * self.dx


class Drive(CellViews):
    """One MDR spring row with its runner, advanced tick by tick.

    Parameters
    ----------
    params : DriveParams
    a_ref : float
        Length scale [m] (normally the contact radius at the nominal forth-step force a1).
        The grid spacing is ``dx = a_ref / resolution``.
    resolution : float
        Cells per ``a_ref`` (springs per contact radius).
    stroke : (float, float)
        Range of the patch centre c = integral of omega R dt [m] that the row must cover.
    a_max : float
        Largest contact half-width that will occur [m].
    t_ref : float
        Time scale [s] used inside the kernel (the nominal excitation period is a good choice).
    grid_offset : float
        Shift of the cells by this fraction of a cell (to measure grid-alignment effects).
    ledger : bool
        Keep the impulse and energy ledger (``Drive.run``, ``Drive.energy``; the default).
        False for a drive that the env's kernel steps: it keeps none (``Drive.run`` refuses
        such a drive); the work array has the same rows either way (``_kernel.work_rows``).
    """

    def __init__(
        self,
        params: DriveParams,
        *,
        a_ref: float,
        resolution: float,
        stroke: tuple[float, float],
        a_max: float,
        t_ref: float,
        grid_offset: float = 0.0,
        ledger: bool = True,
        levels: int = 0,
    ):
        check_range("a_ref", a_ref, 0.0, _INF, lo_open=True, hi_open=True)
        check_range("resolution", resolution, 0.5, 1e5)
        check_range("a_max", a_max, 0.0, _INF, lo_open=True, hi_open=True)
        check_range("t_ref", t_ref, 0.0, _INF, lo_open=True, hi_open=True)
        if not isinstance(params, DriveParams):
            raise ValueError(f"params must be a DriveParams, got {type(params).__name__}")
        stroke = _check_stroke(stroke)
        self.params = params
        self.stroke = stroke
        self.L0 = float(a_ref)
        self.t0 = float(t_ref)
        self.F0 = params.G_star * self.L0**2
        self.M0 = params.G_star * self.L0 * self.t0**2
        self.W0 = self.F0 * self.L0
        dx = a_ref / resolution
        check_range("grid_offset", grid_offset, -1.0, 1.0)
        self.grid = Grid(
            stroke[0] / self.L0, stroke[1] / self.L0, a_max / self.L0, dx / self.L0, grid_offset
        )
        n = self.grid.n
        self.levels = check_int("levels", levels, 0, LEVELS_MAX)
        if n << self.levels > 20_000_000:
            raise ValueError(
                f"the spring row would need {n << self.levels} cells (> 2e7) to "
                f"cover the stroke {stroke[1] - stroke[0]:.3g} m at {resolution:g} "
                f"cells per a_ref and {self.levels} finer levels: lower the "
                "resolution, the levels or the stroke (rolling amplitude)"
            )
        self._p = np.array(
            [
                params.R / self.L0,
                params.E_star / params.G_star,
                self.grid.x_lo,
                self.grid.dx,
                float(self.levels),
            ]
        )
        finite_mu, free, load = params.features
        self._mu = params.mu if finite_mu else None
        self._mass = params.m / self.M0 if free else None
        self._load = params.F_ext / self.F0 if load else None
        self._check_scales()
        if self._mu is not None:
            # mu E*/G* beyond the float range makes every friction limit inf, which the stick
            # count reads as slipping (-inf < -inf is false): the kernel takes mu capped where
            # mu E*/G* = MU_EG_MAX, a limit no finite content reaches either (nothing slides,
            # the same T and slip work; params.mu keeps the value given)
            self._mu = min(self._mu, MU_EG_MAX / self._p[K.P_E_OVER_G])
        # cell work array: contents U, build rows A and B and, with friction only, the friction
        # work rows L (limits, edge release coefficients); U, A, B and L are views of it
        self._ledger = bool(ledger)  # run() keeps the ledger; the env kernel does not
        self.cells = np.zeros((K.work_rows(finite_mu, self._ledger), n << self.levels))
        self.st = np.zeros(K.N_STATE)

    def _check_scales(self):
        """The kernel works in units of a_ref, t_ref and G* a_ref^2: every scale and scaled
        parameter must be a finite normal float, else ValueError naming it (e.g. G_star = 1e-300
        makes E*/G* overflow; the outputs would come back inf or 0)."""
        p = self.params
        tiny = np.finfo(np.float64).tiny
        scales = {
            "E_star/G_star": self._p[K.P_E_OVER_G],
            "R/a_ref": self._p[K.P_R],
            "the force unit G_star a_ref^2": self.F0,
            "the mass unit G_star a_ref t_ref^2": self.M0,
            "the energy unit G_star a_ref^3": self.W0,
        }
        if self._mass is not None and p.m > 0.0:
            scales["m/(G_star a_ref t_ref^2)"] = self._mass
        if self._load is not None:
            scales["|F_ext|/(G_star a_ref^2)"] = abs(self._load)
        for name, x in scales.items():
            if not (math.isfinite(x) and x >= tiny):
                raise ValueError(
                    f"{name} = {x:.3g} leaves the normal float range (finite and >= {tiny:.3g}):"
                    f" the kernel's scaled arithmetic would overflow or underflow; choose R, "
                    f"E_star, G_star, m, F_ext, a_ref and t_ref of compatible sizes (got R = "
                    f"{p.R:g} m, E_star = {p.E_star:g} Pa, G_star = {p.G_star:g} Pa, m = "
                    f"{p.m:g} kg, F_ext = {p.F_ext:g} N, a_ref = {self.L0:g} m, t_ref = "
                    f"{self.t0:g} s)"
                )

    @property
    def kernel_features(self):
        """(mu, mass, load) as the kernel takes them: None where the feature is absent."""
        return self._mu, self._mass, self._load

    @property
    def ledger(self) -> bool:
        """Whether this drive keeps the impulse and energy ledger (set at construction)."""
        return self._ledger

    def __setstate__(self, state):
        # drives pickled before the ledger had rows of its own (a plain ``ledger`` attribute,
        # the work array of either kernel) load with the rows their setting needs
        if "ledger" in state:
            state["_ledger"] = state.pop("ledger")
        state.setdefault("levels", 0)
        self.__dict__.update(state)
        # drives pickled before the level grid: its parameter and state entries are zero
        if self._p.shape[0] < K.N_PARAM:
            self._p = np.concatenate([self._p, np.zeros(K.N_PARAM - self._p.shape[0])])
        if self.st.shape[0] < K.N_STATE:
            self.st = np.concatenate([self.st, np.zeros(K.N_STATE - self.st.shape[0])])
        rows = K.work_rows(self._mu is not None, self._ledger)
        if rows != self.cells.shape[0]:
            cells = np.zeros((rows, self.cells.shape[1]))
            m = min(rows, self.cells.shape[0])
            cells[:m] = self.cells[:m]
            self.cells = cells

    # ------------------------------------------------------------------ state
    def reset(self, c0: float = 0.0, vstar0: float = 0.0) -> None:
        """Release every spring, patch centre at c0 [m] (inside the stroke the grid was built
        for: the default 0 only where the stroke contains it), runner at rest or at vstar0
        [m/s] (finite)."""
        c_lo, c_hi = self.stroke
        try:
            check_range("c0", c0, c_lo, c_hi)
        except ValueError as e:
            raise ValueError(
                f"{e}: the patch centre must start inside the stroke the spring row "
                "was built for (pass c0 inside it, or build the Drive with a stroke "
                "that contains c0)"
            ) from None
        check_range("vstar0", vstar0, -_INF, _INF, lo_open=True, hi_open=True)
        m = self.params.m
        kin0 = 0.0
        if math.isfinite(m):  # the ledger starts from the runner's kinetic energy
            kin0 = 0.5 * m * vstar0 * vstar0 / self.W0
            if not math.isfinite(kin0):  # refused before the state changes
                raise ValueError(
                    f"vstar0 = {vstar0:g} m/s gives the runner (m = {m:g} kg) a "
                    "kinetic energy beyond the float range; choose a smaller "
                    "vstar0"
                )
        self.cells[:] = 0.0  # the scratch and level-grid rows too: a reset drive is a new one
        self.st[:] = 0.0
        self.st[K.ST_C] = c0 / self.L0
        self.st[K.ST_VS] = vstar0 * self.t0 / self.L0
        self.st[K.ST_KIN0] = kin0

    def get_state(self) -> tuple[np.ndarray, np.ndarray]:
        return self.U.copy(), self.st.copy()

    def set_state(self, state) -> None:
        """Restore a state from ``get_state`` of a drive with the same grid: a pair (U, st) of
        finite float arrays of shapes (n cells,) and (N_STATE,); else ValueError."""
        try:
            U, st = state
        except (TypeError, ValueError):
            raise ValueError(
                f"state must be the pair (U, st) that get_state returns, got {type(state).__name__}"
            ) from None
        arrs = {}
        for name, x, shape in (("U", U, self.U.shape), ("st", st, self.st.shape)):
            a = np.asarray(x)
            if a.dtype.kind not in "fiu" or a.shape != shape:
                raise ValueError(
                    f"state {name} must be a real array of shape {shape} (this "
                    f"drive's grid), got dtype {a.dtype} and shape {a.shape}"
                )
            a = a.astype(np.float64)
            if not np.all(np.isfinite(a)):
                raise ValueError(f"state {name} must be finite (got NaN or inf)")
            arrs[name] = a
        self.U[:] = arrs["U"]
        self.st[:] = arrs["st"]

    # ------------------------------------------------------------------ stepping
    def run(self, *, dt_tick: float, n_sub: int, omega_R, v, N=None, d=None, vstar=None):
        """Advance len(omega_R) ticks of length dt_tick [s], n_sub sub-steps each.

        Give the normal force ``N`` [N] or the indentation ``d`` [m] per tick, the signed
        rolling rate ``omega_R`` [m/s] and translation rate ``v`` [m/s] per tick, and the
        runner velocity ``vstar`` [m/s] per tick when the runner is prescribed (m = inf; a free
        runner takes none).
        Returns a dict of per-tick arrays in SI (see ``_kernel.OUT_*``), all finite (an
        overflow is a FloatingPointError): T, impulse, vstar, xstar, slip_work, c, N and
        ``stick_fraction``, the share of the contact length whose cells are below their
        friction limit after the tick's last sub-step ("not slipping now"; 1 with mu = inf
        while in contact).  It counts cells (edge cells by overlap), so it converges at first
        order in dx at best, and it is not the Cattaneo-Mindlin stick zone of the loading
        history: a partly slipping contact that comes to rest unloads from its limits and
        reads 1.0.
        A massless runner (m = 0) under a load with no force equilibrium (|F_ext| above mu N,
        or any load without contact) raises ValueError.  A drive built with ``ledger=False``
        (an env's) raises RuntimeError: its ledger is not kept, and its work array lacks the
        ledger's rows.
        """
        if not self._ledger:
            raise RuntimeError(
                "this drive was built without the energy ledger (an env's "
                "drive, ledger=False): Drive.run keeps the ledger, which this "
                "drive has not kept; build a Drive with ledger=True"
            )
        check_range("dt_tick", dt_tick, 0.0, _INF, lo_open=True, hi_open=True)
        n_sub = check_n_sub(n_sub)
        self._check_state_valid()
        u, vv, dd, vs = self._tick_inputs(omega_R, v, N, d, vstar)
        k = u.shape[0]
        ts = self.t0 / self.L0
        out = np.zeros((k, K.N_OUT))
        # a massless loaded runner can meet a tick without force equilibrium: the error then
        # leaves the drive as it was before this run (the kernel went on through every tick)
        before = (
            self.get_state()
            if self._mass is not None and self._mass == 0.0 and self._load is not None
            else None
        )
        done = K.run_ticks(
            self.cells,
            self.st,
            self._p,
            dd / self.L0,
            u * ts,
            vv * ts,
            vs * ts,
            self._mu,
            self._mass,
            self._load,
            int(n_sub),
            dt_tick / n_sub / self.t0,
            out,
        )
        try:
            self._check_flags()
        except ValueError as e:  # no force equilibrium: say with which numbers
            N_lo = float(hertz_force(dd.min(), self.params.R, self.params.E_star)) if k else 0.0
            if before is not None:
                self.U[:], self.st[:] = before
            raise ValueError(
                f"{e} (F_ext = {self.params.F_ext:g} N, mu = {self.params.mu:g}, "
                f"least normal force of this run N = {N_lo:.6g} N; the drive's "
                "state is as before this run)"
            ) from None
        res = self._to_si(out[:done])
        self._check_finite(out[:done], res, dt_tick)
        return res

    def _tick_inputs(self, omega_R, v, N, d, vstar):
        """``run``'s per-tick inputs checked, as arrays of one length: omega R, v, the
        indentation (from N where N is given) and vstar (zeros for a free runner); the
        contact must stay within the grid's a_max."""
        u = _as_ticks("omega_R", omega_R)
        k = u.shape[0]
        vv = _as_ticks("v", v, k)
        if (N is None) == (d is None):
            raise ValueError("give exactly one of N (normal force) or d (indentation)")
        if N is not None:
            NN = _as_ticks("N", N, k)
            if np.any(NN < 0):
                raise ValueError("N must be >= 0 (no adhesion)")
            dd = hertz_indentation(NN, self.params.R, self.params.E_star)
        else:
            dd = _as_ticks("d", d, k)
            if np.any(dd < 0):
                raise ValueError("d must be >= 0 (no adhesion)")
        if self._mass is None:
            if vstar is None:
                raise ValueError("vstar is required for a prescribed runner (m = inf)")
            vs = _as_ticks("vstar", vstar, k)
        else:
            if vstar is not None:
                raise ValueError(
                    f"vstar is only for a prescribed runner (m = inf); this runner "
                    f"is free (m = {self.params.m:g} kg) and its velocity follows "
                    "from the runner equation: leave vstar out"
                )
            vs = np.zeros(k)
        a_max = float(np.sqrt(self.params.R * dd.max())) / self.L0 if k else 0.0
        if a_max > self.grid.a_max * (1 + 1e-9):
            raise ValueError(
                f"contact half-width {a_max * self.L0:.3e} m exceeds the grid's "
                f"a_max {self.grid.a_max * self.L0:.3e} m"
            )
        return u, vv, dd, vs

    def _check_flags(self, hint="the drive's state is no longer valid (reset() it)"):
        """``check_flags`` of the state; a grid or non-finite error (an invalid state) gets
        ``hint`` appended."""
        try:
            check_flags(self.st)
        except (RuntimeError, FloatingPointError) as e:
            raise type(e)(f"{e}; {hint}") from None

    def _check_state_valid(self):
        """Before a run: a grid or non-finite flag that an earlier run stopped on means the
        state is invalid, so it raises again, saying to reset().  The no-equilibrium flag
        (massless runner) belongs to the inputs of the run that set it: cleared here, so that a
        run whose contact does hold the load is not refused for an earlier one's."""
        self.st[K.ST_FLAG] = float(int(self.st[K.ST_FLAG]) & ~K.FLAG_SLIDE)
        self._check_flags(
            "an earlier run stopped on this error and left the drive's state "
            "invalid: reset() the drive before running it again"
        )

    def _check_finite(self, raw, res, dt_tick):
        """Every returned array and the state (ledger included) must be finite: a float
        overflow in the kernel's arithmetic (a huge dt_tick, rate or load) is a
        FloatingPointError naming what overflowed, never a NaN or inf handed back."""
        # fast path: the largest raw output times the largest SI scale (a NaN or inf makes
        # the max non-finite; an SI overflow makes the product inf)
        scale = max(self.F0, self.F0 * self.t0, self.L0 / self.t0, self.L0, self.W0, 1.0)
        if (
            math.isfinite(float(np.abs(raw).max(initial=0.0)) * scale)
            and math.isfinite(float(np.abs(self.st).max()))
            and np.isfinite(self.U).all()
        ):
            return
        bad = [k for k, a in res.items() if not np.all(np.isfinite(a))]
        if not np.all(np.isfinite(self.st)):
            bad.append("the state / energy ledger")
        if not np.all(np.isfinite(self.U)):
            bad.append("the cell deflections")
        if bad:
            flag = self.st[K.ST_FLAG]
            flag = int(flag) if math.isfinite(flag) else 0
            self.st[K.ST_FLAG] = float(flag | K.FLAG_NONFINITE)  # next run: refused until reset
            raise FloatingPointError(
                f"Drive.run overflowed the float range in {', '.join(bad)} (dt_tick = "
                f"{dt_tick:g} s): reduce dt_tick, the rates omega_R, v, vstar or the load "
                "F_ext; the drive's state is no longer valid (reset() it)"
            )

    def _to_si(self, out):
        F0, L0, t0 = self.F0, self.L0, self.t0
        return {
            "T": out[:, K.OUT_T] * F0,
            "impulse": out[:, K.OUT_IMP] * F0 * t0,
            "vstar": out[:, K.OUT_VS] * L0 / t0,
            "xstar": out[:, K.OUT_XS] * L0,
            "slip_work": out[:, K.OUT_SLIP] * self.W0,
            "c": out[:, K.OUT_C] * L0,
            "N": out[:, K.OUT_N] * F0,
            "stick_fraction": out[:, K.OUT_STICK],
        }

    # ------------------------------------------------------------------ diagnostics
    @property
    def energy(self) -> dict:
        """Cumulative energy terms [J] and the balance residual.

        drive = elastic + release + slip + snap + runner_work, runner_work + ext = kinetic -
        kinetic_start (+ numerical dissipation of the implicit step).  ``slip`` is the Coulomb
        work (wear), ``release`` the elastic energy of springs leaving the contact, ``snap``
        the energy lost beyond the Coulomb work when springs snap to a friction limit that
        dropped (a sudden load drop; O(dt) otherwise), ``kinetic`` the runner's kinetic energy
        now and ``kinetic_start`` at ``reset`` (``vstar0``; 0 for a prescribed runner).
        ``residual`` = drive + ext + kinetic_start - (elastic + release + slip + snap +
        kinetic), i.e. energy lost to discretisation (positive) or created (negative).
        ``work_in`` = |drive| + |ext| + kinetic_start, the scale to judge the residual by.
        """
        if not self.ledger:
            raise RuntimeError(
                "this drive is stepped by the env kernel, which leaves the energy "
                "ledger out of the computation; use Drive.run for energies"
            )
        st, W0 = self.st, self.W0
        elastic = float(K.elastic_energy(self.U, st, self._p)) * W0
        m = self.params.m
        kin = 0.0
        if math.isfinite(m):
            vs = st[K.ST_VS] * self.L0 / self.t0
            kin = 0.5 * m * vs * vs
        e = {
            "drive": st[K.ST_DRIVE] * W0,
            "runner": st[K.ST_RUNNER] * W0,
            "ext": st[K.ST_EXT] * W0,
            "elastic": elastic,
            "release": st[K.ST_REL] * W0,
            "slip": st[K.ST_SLIP] * W0,
            "snap": st[K.ST_SNAP] * W0,
            "kinetic": kin,
            "kinetic_start": st[K.ST_KIN0] * W0,
        }
        lost = e["elastic"] + e["release"] + e["slip"] + e["snap"]
        if math.isfinite(m):
            e["residual"] = e["drive"] + e["ext"] + e["kinetic_start"] - (lost + e["kinetic"])
        else:  # prescribed runner: its work is supplied by whatever prescribes it
            e["residual"] = e["drive"] - e["runner"] - lost
        e["work_in"] = abs(e["drive"]) + abs(e["ext"]) + e["kinetic_start"]
        return e

    def normal_force(self) -> float:
        """Discrete normal force [N]: sum over cells of E* times the exact integral of uN."""
        return float(K.normal_force_sum(self.st, self._p, self.cells.shape[-1])) * self.F0

    @property
    def c(self) -> float:
        return self.st[K.ST_C] * self.L0

    @property
    def vstar(self) -> float:
        return self.st[K.ST_VS] * self.L0 / self.t0

    @property
    def xstar(self) -> float:
        return self.st[K.ST_XS] * self.L0

    @property
    def x_sphere(self) -> float:
        return self.st[K.ST_XSPH] * self.L0

    @property
    def T(self) -> float:
        return self.st[K.ST_T] * self.F0

    @property
    def cell_size(self) -> float:
        """Cell size of the grid level in use (units of a_ref; ``grid.dx`` at level 0)."""
        return self.grid.dx / (1 << int(self.st[K.ST_LEVEL]))

    def profile(self):
        """Cell centres x [m], uT [m], uN [m] and slip flag along the row (for plots)."""
        g = self.grid
        dx, n = self.cell_size, g.n << int(self.st[K.ST_LEVEL])
        x = g.x_lo + (np.arange(n) + 0.5) * dx
        c, a, d = self.st[K.ST_C], self.st[K.ST_A], self.st[K.ST_D]
        xl = g.x_lo + np.arange(n) * dx
        ell = np.clip(np.minimum(xl + dx, c + a) - np.maximum(xl, c - a), 0.0, None)
        uT = np.where(ell > 0, self.U[:n] / np.where(ell > 0, ell, 1.0), 0.0)
        uN = np.clip(d - (x - c) ** 2 / self._p[K.P_R], 0.0, None)
        if self._mu is not None:
            EG = self._p[K.P_E_OVER_G]
            slip = (ell > 0) & (np.abs(uT) >= self._mu * EG * uN * (1 - 1e-9))
        else:
            slip = np.zeros(n, bool)
        return x * self.L0, uT * self.L0, uN * self.L0, slip


N_SUB_MAX = 10**9
LEVELS_MAX = 12  # finest level of a level grid: cells down to dx / 4096
MU_EG_MAX = 1e300  # largest mu E*/G* the kernel takes (sums of limits over cells stay finite)


def check_n_sub(n_sub) -> int:
    """Sub-steps per tick as an int in [1, N_SUB_MAX] (integral floats accepted)."""
    return check_int("n_sub", n_sub, 1, N_SUB_MAX)


def _check_stroke(stroke) -> tuple[float, float]:
    """(c_min, c_max) [m]: two finite numbers, c_min <= c_max."""
    try:
        lo, hi = stroke
    except (TypeError, ValueError):
        raise ValueError(f"stroke must be a pair (c_min, c_max) in m, got {stroke!r}") from None
    lo = check_range("stroke[0]", lo, -_INF, _INF, lo_open=True, hi_open=True)
    hi = check_range("stroke[1]", hi, -_INF, _INF, lo_open=True, hi_open=True)
    if not lo <= hi:
        raise ValueError(f"stroke must satisfy c_min <= c_max, got ({lo}, {hi})")
    return lo, hi


def _as_ticks(name, x, k=None):
    a = np.atleast_1d(as_real_array(name, x))
    if a.ndim != 1:
        raise ValueError(f"{name} must be a scalar or 1-D array of per-tick values")
    if k is not None:
        if a.shape[0] == 1 and k != 1:
            a = np.full(k, a[0])
        elif a.shape[0] != k:
            raise ValueError(f"{name} has {a.shape[0]} ticks, expected {k}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite (got NaN or inf)")
    return a
