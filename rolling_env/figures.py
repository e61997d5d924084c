"""The paper's Figs. 6, 8 and 9 regenerated from the simulation (PNG + CSV under results/paper/).

* Fig. 6: steady force sum (T1 + T2)/(2 G* a1^2) over (v/(omega R), v*/(omega R)), delta 0.93,
  w 2.2, with the simulated zero contour and Eq. 29.
* Fig. 8: period impulse I/(2 G* a1^2 tau) over the same plane, with Eq. 32 and Eq. 29.
* Fig. 9: Eq. 32 working point against v/(omega R) for delta 0.9, 0.7, 0.5 (w 2.2 and 10),
  simulated working points as markers.
"""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from . import analytic
from . import experiments as ex
from .io import atomic_write


def _grid(n):
    return np.linspace(0.0, 1.0, n), np.linspace(0.0, 0.12, n)


def _zero_of_affine(f, eps):
    """v*/(omega R) where f(eps, V) vanishes (f is affine in V)."""
    f0, f1 = f(eps, 0.0), f(eps, 0.1)
    return -0.1 * f0 / (f1 - f0)


def fig_maps(n=41, delta=0.93, w=2.2, resolution=32):
    eps, V = _grid(n)
    fs = np.array([[ex.force_sum(delta, e, w, v, resolution=resolution) for e in eps] for v in V])
    imp = np.array([[ex.period_impulse(delta, e, w, v, resolution=resolution) for e in eps]
                    for v in V])
    zero_fs = np.array([_zero_of_affine(lambda e_, v_: ex.force_sum(delta, e_, w, v_,
                                                                    resolution=resolution), e)
                        for e in eps])
    zero_imp = np.array([_zero_of_affine(lambda e_, v_: ex.period_impulse(
        delta, e_, w, v_, resolution=resolution), e) for e in eps])
    return eps, V, fs, imp, zero_fs, zero_imp


def _csv_text(header, rows):
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(header)
    w.writerows(rows)
    return buf.getvalue()


def make_figures(out="results/paper", n=41, resolution=32) -> dict:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out)
    delta, w = 0.93, 2.2
    eps, V, fs, imp, zero_fs, zero_imp = fig_maps(n, delta, w, resolution)
    e29 = analytic.eq29(delta, eps)
    e32 = analytic.eq32(delta, eps, w)
    dev6 = float(np.max(np.abs(zero_fs - e29)))
    dev8 = float(np.max(np.abs(zero_imp - e32)))

    for name, Z, label, zero, refs in (
            ("fig6_force_sum", fs, r"$(T_1+T_2)/(2G^*a_1^2)$", zero_fs, [("Eq. 29", e29, "k--")]),
            ("fig8_impulse", imp, r"$I/(2G^*a_1^2\tau)$", zero_imp,
             [("Eq. 32", e32, "k--"), ("Eq. 29", e29, "k:")])):
        fig, ax = plt.subplots(figsize=(6, 4.5))
        lim = np.max(np.abs(Z))
        pc = ax.pcolormesh(eps, V, Z, cmap="RdBu_r", vmin=-lim, vmax=lim, shading="auto")
        fig.colorbar(pc, ax=ax, label=label)
        ax.plot(eps, zero, color="gold", lw=2.5, label="simulated zero")
        for lab, y, style in refs:
            ax.plot(eps, y, style, lw=1.2, label=lab)
        ax.set_xlabel(r"$v/(\omega R)$")
        ax.set_ylabel(r"$v^*/(\omega R)$")
        ax.set_ylim(V[0], V[-1])
        ax.set_title(f"{'Fig. 6' if 'fig6' in name else 'Fig. 8'}: delta = {delta}, w = {w}, "
                     f"{resolution:g} springs/a1")
        ax.legend(loc="upper right", fontsize=8)
        fig.tight_layout()
        atomic_write(out / f"{name}.png", lambda p: fig.savefig(p, dpi=110, format="png"))
        plt.close(fig)
        rows = [(e, v, Z[j, i]) for j, v in enumerate(V) for i, e in enumerate(eps)]
        atomic_write(out / f"{name}.csv", lambda p: Path(p).write_text(
            _csv_text(["v_over_omegaR", "vstar_over_omegaR", "value"], rows)))

    # Fig. 9
    fig, ax = plt.subplots(figsize=(6, 4.5))
    e_line = np.linspace(0.0, 1.0, 101)
    e_mark = np.linspace(0.0, 0.9, 7)
    rows9, dev9 = [], 0.0
    for dl, color in ((0.9, "C0"), (0.7, "C1"), (0.5, "C2")):
        for ww, style in ((2.2, "-"), (10.0, "--")):
            ax.plot(e_line, analytic.eq32(dl, e_line, ww), style, color=color,
                    label=f"Eq. 32, delta {dl}, w {ww:g}")
            sim = np.array([ex.working_point(dl, e, ww, resolution=64)["simulated"]
                            for e in e_mark])
            dev9 = max(dev9, float(np.max(np.abs(sim - analytic.eq32(dl, e_mark, ww)))))
            ax.plot(e_mark, sim, "o" if ww == 2.2 else "s", color=color, mfc="none", ms=6)
            rows9 += [(dl, ww, e, s, analytic.eq32(dl, e, ww)) for e, s in zip(e_mark, sim)]
    ax.plot([], [], "ko", mfc="none", label="simulated (zero impulse)")
    ax.set_xlabel(r"$v/(\omega R)$")
    ax.set_ylabel(r"$v^*/(\omega R)$ at the working point")
    ax.set_title("Fig. 9: working point, Eq. 32 vs simulation")
    ax.legend(fontsize=7)
    fig.tight_layout()
    atomic_write(out / "fig9_working_point.png", lambda p: fig.savefig(p, dpi=110, format="png"))
    plt.close(fig)
    atomic_write(out / "fig9_working_point.csv", lambda p: Path(p).write_text(
        _csv_text(["delta", "w", "v_over_omegaR", "simulated", "eq32"], rows9)))
    return {"fig6_max_dev_from_eq29": dev6, "fig8_max_dev_from_eq32": dev8,
            "fig9_max_dev_from_eq32": dev9, "out": str(out)}
