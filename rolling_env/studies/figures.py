"""The paper's Figs. 6, 8 and 9 regenerated from the simulation (PNG + CSV under results/paper/).

* Fig. 6: steady force sum (T1 + T2)/(2 G* a1^2) over (v/(omega R), v*/(omega R)), delta 0.93,
  w 2.2, with the simulated zero line and Eq. 29.
* Fig. 8: period impulse I/(2 G* a1^2 tau) over the same plane, with Eq. 32 and Eq. 29.
* Fig. 9: Eq. 32 working point against v/(omega R) for delta 0.9, 0.7, 0.5 (w 2.2, the paper's
  amplitude, and w 10, close to the Eq. 29 limit), simulated working points as markers.

Both maps are affine in v*/(omega R) (infinite friction, prescribed runner), so the simulated
zero line at each v/(omega R) is found exactly from two runs (``zero_lines``).
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from rolling_env.io import atomic_write, staged, write_text
from rolling_env.physics import analytic
from rolling_env.physics import experiments as ex

FIG_DELTA = 0.93  # paper Figs. 6, 8
FIG_W = 2.2
FIG9_DELTAS = (0.9, 0.7, 0.5)
FIG9_WS = (2.2, 10.0)
EPS_MAX, VSTAR_MAX = 1.0, 0.12  # axes of the maps


def _zero_of_affine(f, eps):
    """v*/(omega R) where f(eps, V) vanishes (f is affine in V)."""
    f0, f1 = f(eps, 0.0), f(eps, 0.1)
    return -0.1 * f0 / (f1 - f0)


def zero_lines(eps, delta=FIG_DELTA, w=FIG_W, resolution=32):
    """Simulated zero lines v*/(omega R) of the force sum (Fig. 6, compare Eq. 29) and of the
    period impulse (Fig. 8, compare Eq. 32) at each v/(omega R) in ``eps``."""
    eps = np.atleast_1d(np.asarray(eps, float))
    zfs = np.array(
        [
            _zero_of_affine(lambda e_, v_: ex.force_sum(delta, e_, w, v_, resolution=resolution), e)
            for e in eps
        ]
    )
    zimp = np.array(
        [
            _zero_of_affine(
                lambda e_, v_: ex.period_impulse(delta, e_, w, v_, resolution=resolution), e
            )
            for e in eps
        ]
    )
    return zfs, zimp


def fig_maps(n=41, delta=FIG_DELTA, w=FIG_W, resolution=32):
    """The two maps on an n x n grid: (eps, V, force_sum[V, eps], impulse[V, eps], zero lines)."""
    eps, V = np.linspace(0.0, EPS_MAX, n), np.linspace(0.0, VSTAR_MAX, n)
    fs = np.array([[ex.force_sum(delta, e, w, v, resolution=resolution) for e in eps] for v in V])
    imp = np.array(
        [[ex.period_impulse(delta, e, w, v, resolution=resolution) for e in eps] for v in V]
    )
    zero_fs, zero_imp = zero_lines(eps, delta, w, resolution)
    return eps, V, fs, imp, zero_fs, zero_imp


def fig9_points(e_mark, resolution=64):
    """Simulated working points for Fig. 9: rows (delta, w, eps, simulated, eq32)."""
    rows = []
    for dl in FIG9_DELTAS:
        for ww in FIG9_WS:
            for e in e_mark:
                sim = ex.working_point(dl, e, ww, resolution=resolution)["simulated"]
                rows.append((dl, ww, float(e), sim, float(analytic.eq32(dl, e, ww))))
    return rows


def _csv_text(header, rows):
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


@staged()  # every file new, or (on any error, an interrupt included) none of them
def make_figures(out="results/paper", n=41, resolution=32, resolution9=64) -> dict:
    """Write fig6_force_sum, fig8_impulse (.png, map .csv, zero line _zero.csv) and
    fig9_working_point (.png, .csv) under ``out``, all of them or none; return the largest
    deviations of the
    simulated zero lines and working points from Eq. 29 / Eq. 32 (in omega R)."""
    import matplotlib

    matplotlib.use("Agg")

    out = Path(out)
    delta, w = FIG_DELTA, FIG_W
    eps, V, fs, imp, zero_fs, zero_imp = fig_maps(n, delta, w, resolution)
    e29 = analytic.eq29(delta, eps)
    e32 = analytic.eq32(delta, eps, w)
    dev6 = float(np.max(np.abs(zero_fs - e29)))
    dev8 = float(np.max(np.abs(zero_imp - e32)))
    title = rf"$\delta$ = {delta}, $w$ = {w}, {resolution:g} springs per $a_1$"
    refs6 = [("Eq. 29 (steady rolling)", e29, "k--")]
    refs8 = [("Eq. 32 (with transition)", e32, "k--"), ("Eq. 29", e29, "k:")]
    _write_map(out, "fig6_force_sum", rf"Fig. 6: {title}", eps, V, fs, zero_fs, refs6, e29, e32)
    _write_map(out, "fig8_impulse", rf"Fig. 8: {title}", eps, V, imp, zero_imp, refs8, e29, e32)
    dev9 = _write_fig9(out, resolution9)
    return {
        "fig6_max_dev_from_eq29": dev6,
        "fig8_max_dev_from_eq32": dev8,
        "fig9_max_dev_from_eq32": dev9,
        "out": str(out),
    }


_MAP_LABELS = {
    "fig6_force_sum": r"force sum $(T_1+T_2)/(2G^*a_1^2)$",
    "fig8_impulse": r"period impulse $I/(2G^*a_1^2\tau)$",
}


def _write_map(out: Path, name, title, eps, V, Z, zero, refs, e29, eq32) -> None:
    """One map (Z[V, eps]) as ``name``.png with its simulated zero line and the reference
    lines ``refs`` ((label, values, style)), ``name``.csv and the zero line ``name``_zero.csv."""
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    lim = float(np.max(np.abs(Z)))
    pc = ax.pcolormesh(eps, V, Z, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
    fig.colorbar(pc, ax=ax, label=_MAP_LABELS[name])
    cs = ax.contour(eps, V, Z, levels=np.linspace(-lim, lim, 13), colors="0.35", linewidths=0.5)
    ax.clabel(cs, fontsize=6, fmt="%.2f")
    ax.plot(eps, zero, color="gold", lw=3, label="simulated zero")
    for lab, y, style in refs:
        ax.plot(eps, y, style, lw=1.2, label=lab)
    ax.set_xlabel(r"$v/(\omega R)$ (translation / rolling rate)")
    ax.set_ylabel(r"$v^*/(\omega R)$ (runner velocity)")
    ax.set_xlim(0.0, EPS_MAX)
    ax.set_ylim(0.0, VSTAR_MAX)
    ax.set_title(title, fontsize=10)
    ax.legend(loc="upper right", fontsize=8, framealpha=0.9)
    fig.tight_layout()
    atomic_write(out / f"{name}.png", lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)
    rows = [(e, v, Z[j, i]) for j, v in enumerate(V) for i, e in enumerate(eps)]
    write_text(
        out / f"{name}.csv", _csv_text(["v_over_omegaR", "vstar_over_omegaR", "value"], rows)
    )
    write_text(
        out / f"{name}_zero.csv",
        _csv_text(
            ["v_over_omegaR", "simulated_zero", "eq29", "eq32"],
            [(e, z, a, b) for e, z, a, b in zip(eps, zero, e29, eq32)],
        ),
    )


def _write_fig9(out: Path, resolution9) -> float:
    """Fig. 9 (.png, .csv): Eq. 32 against simulated working points; returns the largest
    deviation of a simulated point from Eq. 32 (in omega R)."""
    import matplotlib.pyplot as plt

    e_line = np.linspace(0.0, 1.0, 101)
    e_mark = np.linspace(0.0, 0.9, 7)
    rows9 = fig9_points(e_mark, resolution9)
    dev9 = max(abs(r[3] - r[4]) for r in rows9)
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    for dl, color in zip(FIG9_DELTAS, ("C0", "C1", "C2")):
        for ww, style, mk in zip(FIG9_WS, ("-", "--"), ("o", "s")):
            ax.plot(
                e_line,
                analytic.eq32(dl, e_line, ww),
                style,
                color=color,
                label=rf"Eq. 32, $\delta$ = {dl}, $w$ = {ww:g}",
            )
            sel = [r for r in rows9 if r[0] == dl and r[1] == ww]
            ax.plot([r[2] for r in sel], [r[3] for r in sel], mk, color=color, mfc="none", ms=6)
    ax.plot([], [], "ko", mfc="none", label=f"simulated, $w$ = {FIG9_WS[0]:g}")
    ax.plot([], [], "ks", mfc="none", label=f"simulated, $w$ = {FIG9_WS[1]:g}")
    ax.set_xlabel(r"$v/(\omega R)$ (translation / rolling rate)")
    ax.set_ylabel(r"working point $v^*/(\omega R)$")
    ax.set_title(
        f"Fig. 9: working point, Eq. 32 vs simulation ({resolution9:g} springs per "
        r"$a_1$)",
        fontsize=10,
    )
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(bottom=0.0)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    atomic_write(out / "fig9_working_point.png", lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)
    write_text(
        out / "fig9_working_point.csv",
        _csv_text(["delta", "w", "v_over_omegaR", "simulated", "eq32"], rows9),
    )
    return dev9
