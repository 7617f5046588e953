"""Figures: the array, the passages and the measurement traces."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

_MARKERS = {"magnetometer": ("s", "tab:blue"), "electrode": ("^", "tab:orange"), "accelerometer": ("o", "tab:green")}
_DISPLAY = {"T": (1e9, "nT"), "V/m": (1e6, "µV/m"), "rad": (180 / np.pi, "deg")}


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
    fig = plt.figure(figsize=(13, max(5.0, 1.9 * n_sensors)), layout="constrained")
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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
