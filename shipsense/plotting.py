"""Figures: the array, the passages and the measurement traces.

The figures a command writes to a file are ``matplotlib.figure.Figure`` objects drawn by the Agg canvas
without pyplot (whose import and figure manager a command that writes one PNG does not need); ``plt``, pyplot
on the Agg backend, is imported on first use (``from shipsense.plotting import plt``) for the figures that are
shown or rendered to arrays.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

_MARKERS = {"magnetometer": ("s", "tab:blue"), "electrode": ("^", "tab:orange"), "accelerometer": ("o", "tab:green")}
_DISPLAY = {"T": (1e9, "nT"), "V/m": (1e6, "µV/m"), "rad": (180 / np.pi, "deg")}


def __getattr__(name):
    """``plt``: matplotlib's pyplot on the Agg backend, imported on first use."""
    if name == "plt":
        import matplotlib.pyplot as plt

        return plt
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def save_png(fig, path, dpi=110):
    """Write ``fig`` (a ``matplotlib.figure.Figure``) to ``path``; a PNG with zlib's fastest level (a
    figure of mostly flat colour: a fifth larger, encoded in about half the time of the default level)."""
    png = str(path).lower().endswith(".png")
    fig.savefig(path, dpi=dpi, **({"pil_kwargs": {"compress_level": 1}} if png else {}))
    return path


def figure_to_rgb(fig):
    """The rendered figure as an (H, W, 3) uint8 array; the figure is closed."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()
    img = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    __getattr__("plt").close(fig)
    return img


def show_image(path, dpi=110):
    """A figure showing the PNG ``path`` (a figure a command wrote) at its own size (``dpi`` pixels an inch):
    how the docs' gallery shows the commands' figures as they wrote them."""
    plt = __getattr__("plt")
    image = plt.imread(path)
    fig = plt.figure(figsize=(image.shape[1] / dpi, image.shape[0] / dpi))
    fig.figimage(image, resize=True)
    return fig


def frame_map(ax, points, margin):
    """Frame the map ``ax`` (east, north in m, equal aspect) around ``points`` (a list of (k, 2) arrays) with a
    margin of ``margin`` of their extent plus 20 m."""
    span = np.concatenate(points)
    lo, hi = span.min(axis=0), span.max(axis=0)
    pad = margin * max(hi - lo) + 20
    ax.set_xlim(lo[0] - pad, hi[0] + pad)
    ax.set_ylim(lo[1] - pad, hi[1] + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")


def draw_array(ax, array, label=True):
    """Sensors of a :class:`~shipsense.physics.array.SensorArray` on a map (x east, y north)."""
    for t, (marker, color) in _MARKERS.items():
        idx = array.group(t)
        if idx.size:
            ax.scatter(array.positions[idx, 0], array.positions[idx, 1], marker=marker, s=60, color=color,
                       edgecolor="k", zorder=5, label=f"{t} ({idx.size})")
    if label:
        done = set()
        for sid, pos in zip(array.ids, array.positions):
            key = tuple(np.round(pos[:2], 3))
            if key in done:
                continue
            done.add(key)
            ax.annotate(sid, pos[:2], textcoords="offset points", xytext=(5, 5), fontsize=7)


def plot_simulation(sim, path, max_runs=20, max_sensors=8):
    """Map of the array and passages, and the measurement traces of run 0, to a PNG."""
    array = sim.array
    n_sensors = min(len(array.ids), max_sensors)
    fig = Figure(figsize=(13, max(5.0, 1.9 * n_sensors)), layout="constrained")
    grid = fig.add_gridspec(n_sensors, 2, width_ratios=[1.1, 1.4])
    ax = fig.add_subplot(grid[:, 0])
    for r in range(min(sim.runs, max_runs)):
        xy = sim.truth[r, :, :2]
        ax.plot(xy[:, 0], xy[:, 1], "-", color="0.3" if r else "tab:red", lw=1.5 if r == 0 else 0.7,
                alpha=1.0 if r == 0 else 0.5, label="passage (run 0)" if r == 0 else None)
        ax.plot(xy[0, 0], xy[0, 1], "o", color="tab:red" if r == 0 else "0.3", ms=4)
        ax.annotate("", xy[-1], xy[-2], arrowprops=dict(arrowstyle="->", color="tab:red" if r == 0 else "0.3"))
    draw_array(ax, array)
    ax.set_aspect("equal", adjustable="datalim")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    shown = "passage" if sim.runs == 1 else f"{min(sim.runs, max_runs)} passages"
    ax.set_title(f"{sim.scenario.name}: array and {shown}")
    ax.grid(alpha=0.3)
    ax.legend(loc="best", fontsize=8)

    units = array.channel_units
    sensor_of = array.channel_sensor
    for s in range(n_sensors):
        a = fig.add_subplot(grid[s, 1])
        cols = np.flatnonzero(sensor_of == s)
        scale, unit = _DISPLAY[units[cols[0]]]
        for c in cols:
            line, = a.plot(sim.times, scale * sim.clean[0, :, c], lw=1.2, label=array.channels[c][1])
            a.plot(sim.times, scale * sim.measurements[0, :, c], ".", ms=2, color=line.get_color(), alpha=0.6)
        a.set_ylabel(f"{array.ids[s]}\n[{unit}]", fontsize=8)
        a.legend(loc="upper right", fontsize=7, ncols=len(cols))
        a.grid(alpha=0.3)
        if s == n_sensors - 1:
            a.set_xlabel("time [s]  (lines: noise-free, dots: measured; run 0)")
    if len(array.ids) > max_sensors:
        fig.suptitle(f"traces of the first {max_sensors} of {len(array.ids)} sensors", fontsize=9)
    return save_png(fig, path)


def _ellipse(ax, mean, cov, color, nsig=2.0):
    w, V = np.linalg.eigh(cov)
    w = np.sqrt(np.clip(w, 0, None)) * nsig
    t = np.linspace(0, 2 * np.pi, 40)
    pts = mean[:, None] + V @ (w[:, None] * np.stack([np.cos(t), np.sin(t)]))
    ax.plot(pts[0], pts[1], "-", color=color, lw=0.8, alpha=0.8)


def plot_track(summary, times, path, truth=None, title=None, ellipses=8):
    """A tracked passage (:class:`~shipsense.cli.track.TrackSummary`) to a PNG: the array, the truth (if known)
    and the estimated track with 2-sigma ellipses, coloured by status; and over time the position error
    against the reported 2-sigma (or the 2-sigma alone); with motion modes, their probabilities over time (the
    selected hypothesis's, stacked).  A passage the tracker never tracked (one sample, no
    field above the noise) draws the array and says so; nothing is drawn on a log scale that has no positive
    value."""
    from shipsense.trackers.tracker.results import INITIALISING, STATUSES

    pl = summary.plot
    k, est, cov, status = pl["k"], pl["estimate"], pl["cov"][:, :2, :2], pl["status"]
    t = np.asarray(times)[k]
    tracked = (status > INITIALISING) & np.isfinite(est[:, :2]).all(axis=1)
    modes = pl.get("modes")
    names = summary.tracker.mode_names
    with_modes = modes is not None and len(names) > 0 and modes.ndim == 2 and modes.shape[1] == len(names)
    # fixed margins, not a layout engine: the constrained layout measured every text twice per figure
    if with_modes:   # the motion modes' probabilities under the error panel
        fig = Figure(figsize=(14, 7.5))
        axd = fig.subplot_mosaic([["map", "error"], ["map", "modes"]], width_ratios=[1.3, 1],
                                 height_ratios=[1.6, 1])
        fig.subplots_adjust(left=0.06, right=0.98, bottom=0.08, top=0.94, wspace=0.18, hspace=0.32)
        ax = [axd["map"], axd["error"]]
    else:
        fig = Figure(figsize=(14, 6.5))
        ax = fig.subplots(1, 2, width_ratios=[1.3, 1])
        fig.subplots_adjust(left=0.06, right=0.98, bottom=0.09, top=0.93, wspace=0.18)
    a = ax[0]
    if truth is not None:
        a.plot(truth[:, 0], truth[:, 1], "-", color="tab:red", lw=2, label="truth")
    if tracked.any():
        a.plot(est[tracked, 0], est[tracked, 1], "-", color="tab:blue", lw=1.6, label="estimate (tracking)")
    else:
        a.text(0.5, 0.96, f"no estimate: the tracker did not start tracking in {summary.samples} sample"
               f"{'s' if summary.samples != 1 else ''}", transform=a.transAxes,
               ha="center", va="top", fontsize=9, color="0.3")
    colours = {2: "tab:blue", 3: "tab:green", 4: "tab:orange", 5: "tab:purple"}
    for code, colour in colours.items():
        at = (status == code) & tracked
        if at.any() and code != 2:
            a.plot(est[at, 0], est[at, 1], "o", ms=4, color=colour, label=STATUSES[code])
    shown = np.flatnonzero(tracked)
    for i in shown[np.linspace(0, shown.size - 1, min(ellipses, shown.size)).astype(int)] if shown.size else []:
        _ellipse(a, est[i, :2], cov[i], colours.get(int(status[i]), "tab:blue"))
    draw_array(a, summary.tracker.model.array)
    frame_map(a, [est[tracked, :2], summary.tracker.model.array.positions[:, :2]]
              + ([truth[:, :2]] if truth is not None else []), margin=0.15)
    a.grid(alpha=0.3)
    a.legend(fontsize=8, loc="lower left")
    a.set_title(title or "tracked passage (2-sigma ellipses)")
    b = ax[1]
    two_sigma = 2 * np.sqrt(np.maximum(np.linalg.eigvalsh(cov)[:, -1], 0.0))
    curves = [two_sigma[tracked]]
    b.plot(t[tracked], two_sigma[tracked], "-", color="tab:blue", label="reported 2-sigma (major axis)")
    if truth is not None:
        err = np.hypot(*(est[:, :2] - truth[k, :2]).T)
        b.plot(t[tracked], err[tracked], "-", color="tab:red", lw=1, label="position error")
        curves.append(err[tracked])
    for code, colour in ((1, "0.8"), (4, "tab:orange")):
        if np.any(status == code):
            b.fill_between(t, 0, 1, where=status == code, step="mid", transform=b.get_xaxis_transform(),
                           color=colour, alpha=0.3, lw=0, label=STATUSES[code])
    values = np.concatenate(curves)
    if np.any(np.isfinite(values) & (values > 0)):
        from matplotlib.ticker import FormatStrFormatter, NullFormatter

        b.set_yscale("log")
        b.yaxis.set_major_formatter(FormatStrFormatter("%g"))   # plain numbers: no mathtext to lay out
        b.yaxis.set_minor_formatter(NullFormatter())
    else:
        b.text(0.5, 0.5, "no sample tracked: no uncertainty or error to show", transform=b.transAxes,
               ha="center", va="center", fontsize=9, color="0.3")
    if t.size == 1:
        b.set_xlim(t[0] - 1.0, t[0] + 1.0)
    b.set_xlabel("time [s]")
    b.set_ylabel("m")
    b.grid(alpha=0.3, which="both")
    if b.get_legend_handles_labels()[0]:
        b.legend(fontsize=8, loc="upper right")
    b.set_title("error against the reported uncertainty")
    if with_modes:
        m = axd["modes"]
        known = np.isfinite(modes).all(axis=1)
        m.stackplot(t[known], modes[known].T, labels=[name.replace("_", " ") for name in names], alpha=0.8,
                    step="mid")
        m.set_xlim(b.get_xlim())
        m.set_ylim(0, 1)
        m.set_xlabel("time [s]")
        m.set_ylabel("probability")
        m.grid(alpha=0.3)
        m.legend(fontsize=8, loc="upper left", ncol=len(names), framealpha=0.9)
        m.set_title("motion modes (the selected hypothesis's)")
        b.set_xlabel("")
    return save_png(fig, path)


def plot_ships(result, array, path=None, *, truth=None, present=None, title=None, ellipses=6):
    """Several ships tracked in one passage: the array, the true ships (if known, dashed), every track in its own
    colour with 2-sigma ellipses; over time the number of ships and, with the truth, GOSPA.

    Parameters
    ----------
    result : ShipsResult
        The several-ship tracker's result (:class:`~shipsense.trackers.ships.results.ShipsResult`); its first
        passage is drawn.
    array : SensorArray
        The sensors (:class:`~shipsense.physics.array.SensorArray`).
    path : path-like, optional
        Where to write the PNG; None: the figure is returned, open.
    truth : ndarray, shape (J, K, >= 2), optional
        The true ships (x, y first, m; NaN where a ship does not sail).
    present : ndarray of bool, shape (J, K), optional
        Which true ships count at each sample for the number of ships and GOSPA (default: every sailing ship;
        e.g. only those within the array's reach).
    title : str, optional
    ellipses : int
        2-sigma ellipses drawn per track.

    Notes
    -----
    GOSPA (:func:`~shipsense.trackers.metrics.gospa`, :math:`p = \\alpha = 2`, cut-off
    :data:`~shipsense.trackers.metrics.GOSPA_CUTOFF_M`) is drawn with its parts, each as the length it adds,
    :math:`\\sqrt{\\text{part}}`, m: the assigned ships' localisation error and :math:`c / \\sqrt 2` per missed
    or false ship.
    """
    from shipsense.trackers.metrics import GOSPA_CUTOFF_M, gospa

    est, cov, T = result.estimates[0], result.covs[0], result.times[0]
    colours = ("tab:blue", "tab:orange", "tab:green")
    counted = None
    if truth is not None:
        truth = np.asarray(truth, dtype=float)
        counted = np.isfinite(truth[..., 0]) & (True if present is None else np.asarray(present, dtype=bool))
    if path is None:   # a figure pyplot manages (a notebook's or the gallery's to show)
        import matplotlib.pyplot as plt

        fig = plt.figure(figsize=(13, 6.5))
    else:
        fig = Figure(figsize=(13, 6.5))
    grid = fig.add_gridspec(2 if truth is not None else 1, 2, width_ratios=[1.3, 1], left=0.07, right=0.98,
                            bottom=0.09, top=0.92, wspace=0.2, hspace=0.35)
    a = fig.add_subplot(grid[:, 0])
    pts = [array.positions[:, :2]]
    if truth is not None:
        for j, tr in enumerate(truth):
            a.plot(tr[:, 0], tr[:, 1], "--", color="0.4", lw=1.2, label="truth" if j == 0 else None)
            pts.append(tr[np.isfinite(tr[:, 0]), :2])
    for s in range(est.shape[1]):
        on = np.flatnonzero(result.present[0, :, s])
        if on.size == 0:
            continue
        c = colours[s % len(colours)]
        a.plot(est[on, s, 0], est[on, s, 1], "-", color=c, lw=1.6, label=f"ship {s + 1}")
        a.plot(*est[on[0], s, :2], "o", color=c, ms=5)
        for i in on[np.linspace(0, on.size - 1, min(ellipses, on.size)).astype(int)]:
            _ellipse(a, est[i, s, :2], cov[i, s, :2, :2], c)
        pts.append(est[on, s, :2])
    draw_array(a, array)
    frame_map(a, pts, margin=0.1)
    a.grid(alpha=0.3)
    a.legend(loc="best", fontsize=8)
    a.set_title(title or "tracks (2-sigma ellipses; a dot where each begins)")
    b = fig.add_subplot(grid[0, 1])
    b.step(T, result.ship_count[0], where="mid", color="k", label="tracked")
    if counted is not None:
        b.step(T, counted.sum(axis=0), where="mid", color="tab:red", ls="--",
               label="true" + ("" if present is None else " (counted)"))
    b.set_ylabel("ships")
    b.set_yticks(range(0, est.shape[1] + 2))
    b.grid(alpha=0.3)
    b.legend(loc="best", fontsize=8)
    b.set_title("number of ships")
    if counted is None:
        b.set_xlabel("time [s]")
    else:
        g = gospa(est, np.where(counted.T[..., None], np.moveaxis(truth, 0, 1), np.nan))
        d = fig.add_subplot(grid[1, 1], sharex=b)
        for part, colour in (("localisation", "tab:blue"), ("missed", "tab:red"), ("false", "tab:purple")):
            d.fill_between(T, 0, np.sqrt(getattr(g, part)), step="mid", color=colour, alpha=0.3, lw=0, label=part)
        d.step(T, g.total, where="mid", color="k", lw=1.4, label="GOSPA")
        d.set_xlabel("time [s]")
        d.set_ylabel("m")
        d.grid(alpha=0.3)
        d.legend(loc="best", fontsize=8, ncol=2)
        d.set_title(f"GOSPA (p = 2, alpha = 2, c = {GOSPA_CUTOFF_M:g} m) and its parts")
    if path is None:
        return fig
    return save_png(fig, path)


def plot_design(candidates, weights, chosen, truth, path, title=""):
    """Candidates coloured by relaxation weight, the chosen sensors, and the design passages."""
    fig = Figure(figsize=(7.5, 6.5), layout="constrained")
    ax = fig.subplots()
    for r in range(len(truth)):
        t = np.linspace(0, 60, 50)
        xy = truth[r, :2] + t[:, None] * truth[r, 2:4]
        ax.plot(xy[:, 0], xy[:, 1], "-", color="0.7", lw=0.8, label="design passages" if r == 0 else None)
    sc = ax.scatter(candidates[:, 0], candidates[:, 1], c=weights, cmap="viridis", vmin=0, vmax=1, s=30,
                    edgecolor="k", linewidth=0.3)
    ax.scatter(candidates[chosen, 0], candidates[chosen, 1], s=160, facecolor="none", edgecolor="tab:red", lw=2,
               label="chosen")
    fig.colorbar(sc, ax=ax, label="relaxation weight w_i")
    pad = 0.2 * np.ptp(candidates[:, :2], axis=0).max() + 5
    ax.set_xlim(candidates[:, 0].min() - pad, candidates[:, 0].max() + pad)
    ax.set_ylim(candidates[:, 1].min() - pad, candidates[:, 1].max() + pad)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    return save_png(fig, path)


def plot_bound_map(array, xs, ys, bound, path, title=""):
    """Map of the position bound (m, log colour scale) with the array."""
    from matplotlib.colors import LogNorm

    fig = Figure(figsize=(7.5, 6.5), layout="constrained")
    ax = fig.subplots()
    finite = np.isfinite(bound) & (bound > 0)
    vmin = bound[finite].min() if finite.any() else 1e-3
    vmax = bound[finite].max() if finite.any() else 1.0
    mesh = ax.pcolormesh(xs, ys, np.where(finite, bound, np.nan), norm=LogNorm(vmin=vmin, vmax=max(vmax, vmin * 10)),
                         cmap="magma_r", shading="nearest")
    fig.colorbar(mesh, ax=ax, label="position CRLB sqrt(trace) [m]")
    draw_array(ax, array)
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x east [m]")
    ax.set_ylabel("y north [m]")
    ax.set_title(title, fontsize=10)
    return save_png(fig, path)
