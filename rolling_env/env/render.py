"""Frames of RollingDrive-v0: the contact along the spring row and the runner against its target.

Each env keeps its own figure and window in a dict (``state``, held by the env): two envs
rendering at once do not share a window, and closing one leaves the other's open."""

from __future__ import annotations

import numpy as np


def _figure(state: dict):
    if "fig" not in state:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        fig = Figure(figsize=(6.4, 4.8), dpi=100)
        FigureCanvasAgg(fig)
        state["fig"] = fig
    return state["fig"]


def render_frame(env, state: dict) -> np.ndarray:
    """uint8 (480, 640, 3) frame: top, normal deflection (line, left axis) and tangential
    deflection (bars, right axis) along the row with stick (blue) and slip (red) cells; bottom,
    runner displacement against the target.  The small font is set for the frame only: the
    caller's matplotlib settings stay as they were."""
    import matplotlib

    with matplotlib.rc_context({"font.size": 8}):
        return _draw(env, state)


def _draw(env, state: dict) -> np.ndarray:
    fig = _figure(state)
    fig.clear()
    ax1, ax2 = fig.subplots(2, 1)
    drv = env.drive
    x, uT, uN, slip = drv.profile()
    a = max(env.a_max, 1e-30)
    inc = uN > 0
    um = 1e9
    ax1.plot(x / a, uN * um, color="0.3", lw=1, label="normal deflection uN [nm]")
    ax1b = ax1.twinx()
    ax1b.bar(
        (x / a)[inc & ~slip],
        (uT * um)[inc & ~slip],
        width=drv.cell_size,
        color="tab:blue",
        label="uT stick [nm]",
    )
    ax1b.bar(
        (x / a)[inc & slip],
        (uT * um)[inc & slip],
        width=drv.cell_size,
        color="tab:red",
        label="uT slip [nm]",
    )
    ax1.set_zorder(ax1b.get_zorder() + 1)  # the normal profile on top of the bars
    ax1.patch.set_visible(False)
    ax1.set_xlim(-env.scene.stroke_roll / a - 1.2, env.scene.stroke_roll / a + 1.2)
    ax1.set_xlabel("x / a_max (frame of the sphere)")
    ax1.set_ylabel("uN [nm] (line)")
    ax1b.set_ylabel("uT [nm] (bars)")
    lines, labels = ax1.get_legend_handles_labels()
    bars, bar_labels = ax1b.get_legend_handles_labels()
    ax1.legend(lines + bars, labels + bar_labels, loc="upper left", fontsize=7)
    o = env._info()
    ax1.set_title(
        f"{env.scene.name}: N = {o['N']:.3g} N, T = {o['T']:.3g} N, "
        f"stick {100 * o['stick_fraction']:.0f}%"
    )
    h = np.asarray(env._history)
    t = np.arange(h.size) * env.dt * 1e3
    ax2.plot(t, h * um, color="tab:green", label="runner x*")
    ax2.axhline(env.target * um, color="k", ls="--", lw=1, label="target")
    tol = env.scene.tolerance * um
    ax2.axhspan(env.target * um - tol, env.target * um + tol, color="k", alpha=0.1)
    ax2.set_xlabel("t [ms]")
    ax2.set_ylabel("x* [nm]")
    ax2.legend(loc="lower right")
    fig.tight_layout()
    fig.canvas.draw()
    buf = np.asarray(fig.canvas.buffer_rgba())
    return np.ascontiguousarray(buf[:, :, :3], dtype=np.uint8)


def show(frame: np.ndarray, state: dict) -> None:
    import matplotlib.pyplot as plt

    if "win" not in state:
        plt.ion()
        state["win"] = plt.figure()
        state["win"].canvas.manager.set_window_title("RollingDrive-v0")
        state["img"] = state["win"].add_subplot(111).imshow(frame)
        state["win"].axes[0].axis("off")
    else:
        state["img"].set_data(frame)
    state["win"].canvas.draw_idle()
    plt.pause(0.001)


def close(state: dict) -> None:
    if "win" in state:
        import matplotlib.pyplot as plt

        plt.close(state.pop("win"))
        state.pop("img", None)
