"""``shipsense track --data`` start-up: the command imports only what it uses (benchmarks/track_startup.py
measures the time), and the figures are drawn without pyplot, the same pixels as through it."""

import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
UNUSED = ("matplotlib.pyplot", "shipsense.trackers.ships", "shipsense.simulator", "shipsense.envs.passage_v1")


def test_tracking_a_recording_imports_nothing_it_does_not_use(tmp_path):
    """A recording tracked and drawn in a fresh process: no environment, no pyplot, no several-ship tracker, no
    simulator."""
    from shipsense.recording import write_recording
    from shipsense.simulator import simulate

    rec = tmp_path / "rec.csv"
    write_recording(simulate("S2", runs=1, seed=4, random=True), rec)
    code = ("import sys; from shipsense.cli.main import main; "
            f"code = main(['--quiet', 'track', 'S2', '--data', {str(rec)!r}, '--out', {str(tmp_path / 'out')!r}]); "
            f"print(code, *[m for m in {UNUSED!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, cwd=ROOT)
    assert out.stdout.split()[-1] == "0", out.stdout      # exit 0, and none of UNUSED imported
    assert (tmp_path / "out" / "track.png").stat().st_size > 0


def test_plt_arrives_on_first_use_and_a_figure_without_pyplot_draws_the_same_pixels():
    """``shipsense.plotting`` imports no pyplot until ``plt`` is asked for; a figure drawn on its own canvas
    (as the commands write them) equals the same figure made through pyplot, pixel for pixel."""
    code = ("import sys, shipsense.plotting as p; before = 'matplotlib.pyplot' in sys.modules; "
            "from shipsense.plotting import plt; print(before, 'matplotlib.pyplot' in sys.modules, plt.__name__)")
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True, cwd=ROOT)
    assert out.stdout.split() == ["False", "True", "matplotlib.pyplot"]
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from shipsense.plotting import figure_to_rgb, plt

    def draw(fig):
        ax = fig.subplots(1, 2, width_ratios=[1.3, 1])
        ax[0].plot(np.arange(10.0), np.arange(10.0) ** 2, "-o", label="a")
        ax[0].legend()
        ax[1].set_yscale("log")
        ax[1].plot(np.arange(1.0, 11.0), np.exp(np.arange(10.0)))
        return fig

    own = draw(Figure(figsize=(6, 3)))
    FigureCanvasAgg(own).draw()
    np.testing.assert_array_equal(np.asarray(own.canvas.buffer_rgba())[..., :3],
                                  figure_to_rgb(draw(plt.figure(figsize=(6, 3)))))
