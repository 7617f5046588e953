"""The command line's parser: every command and its flags."""

from __future__ import annotations

import argparse
import sys

from shipsense.arguments import whole_flag
from shipsense.cli.agents import cmd_evaluate, cmd_train
from shipsense.cli.common import EXIT_BAD_INPUT, PASSAGES_MAX, RUNS_MAX, SEED, TIMESTEPS_MAX
from shipsense.cli.layouts import cmd_check, cmd_design
from shipsense.cli.passages import cmd_demo, cmd_scenarios, cmd_simulate, cmd_track
from shipsense.cli.studies import cmd_reproduce, cmd_sweep


class Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, exit 2 (the usage is one --help away)
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message} (see {self.prog} --help)\n")

    def parse_known_args(self, args=None, namespace=None):
        # argparse reads "--flag=--" as an empty list, bypassing the flag's type (a crash further on)
        for a in (sys.argv[1:] if args is None else args):
            if isinstance(a, str) and a.startswith("--") and a.endswith("=--"):
                self.error(f"argument {a[:-3]}: expected a value, got '--'")
        return super().parse_known_args(args, namespace)


def build_parser() -> argparse.ArgumentParser:
    from shipsense import __version__

    p = Parser(prog="shipsense", description="Track ships from their influence fields on seabed sensors, "
                "and design the arrays.")
    p.add_argument("--version", action="version", version=f"shipsense {__version__}")
    p.add_argument("--debug", action="store_true", help="show the traceback of an unexpected error")
    p.add_argument("--quiet", dest="no_progress", action="store_true",
                   help="no progress bars (they are shown only on a terminal in any case)")
    sub = p.add_subparsers(dest="command", required=True, parser_class=Parser)
    from shipsense.budget import MEMORY_LIMIT_GB, TIME_LIMIT_MINUTES

    limits = argparse.ArgumentParser(add_help=False)   # the work budget, on every command that can be large
    limits.add_argument("--max-memory", type=float, default=MEMORY_LIMIT_GB, metavar="GB",
                        help="refuse work whose memory is estimated above this (default: %(default)g GB)")
    limits.add_argument("--max-minutes", type=float, default=TIME_LIMIT_MINUTES, metavar="MIN",
                        help="refuse work whose run time is estimated above this (default: %(default)g minutes)")

    d = sub.add_parser("demo", help="simulate a passage past the default array and plot it")
    d.add_argument("--out", default="shipsense-demo", help="output directory (default: %(default)s)")
    d.set_defaults(func=cmd_demo)

    s = sub.add_parser("scenarios", help="list the shipped scenarios")
    s.set_defaults(func=cmd_scenarios)

    m = sub.add_parser("simulate", parents=[limits], help="simulate passages of a scenario")
    m.add_argument("scenario", help="a shipped scenario name (see `shipsense scenarios`) or a TOML file")
    m.add_argument("--runs", type=whole_flag(1, RUNS_MAX), default=None,
                   help="Monte Carlo runs (default: the scenario's)")
    m.add_argument("--seed", type=SEED, default=None, help="random seed (default: the scenario's)")
    m.add_argument("--random", action="store_true", help="draw passages from the scenario's [prior]")
    m.add_argument("--out", default=None,
                   help="write measurements to FILE.npz, or as a recording: a tidy FILE.csv, FILE.nc (NetCDF/HDF5) or "
                        "FILE.mseed (miniSEED, one run)")
    m.add_argument("--plot", default=None, help="write a picture of the array, passages and traces to FILE.png")
    m.add_argument("--truth", default=None, metavar="FILE.csv",
                   help="write the true states to FILE.csv: run, ship, step, time and the state (SI), one row per "
                        "run, ship and sample (ship 0: the scenario's passage; more with a [traffic] table)")
    m.set_defaults(func=cmd_simulate)

    t = sub.add_parser("track", parents=[limits], help="track a simulated passage, or a recorded one (--data)")
    t.add_argument("scenario", help="a shipped scenario name or a TOML file (the array, medium and tracker)")
    t.add_argument("--data", nargs="+", default=None, metavar="FILE",
                   help="recordings to track (CSV time,sensor,channel,value; NetCDF/HDF5; miniSEED), folders of "
                        "them or glob patterns; several: one folder each in --out and a summary.csv")
    t.add_argument("--mapping", default=None, metavar="FILE.toml",
                   help="renames of the recordings' sensor and channel names, and the NetCDF variable's names")
    t.add_argument("--passage-gap", type=float, default=None, metavar="SECONDS",
                   help="split a recording into passages at gaps longer than this (default: 10 times the "
                        "tracker's gap limit)")
    t.add_argument("--no-plot", action="store_true", help="write the tables only, no track.png")
    t.add_argument("--method", choices=["tracker", "bank"], default="tracker",
                   help="tracker: the project's tracker (default); bank: the source studies' bank")
    t.add_argument("--filter", default=None,
                   help="filter unit (default: ukf for the tracker, huber_ukf when robust; the bank: the scenario's)")
    t.add_argument("--ships", choices=["1", "2", "auto"], default="1",
                   help="the most ships tracked at once: 1, the one-ship tracker (default); 2 or auto (the same "
                        "today): the several-ship tracker, an option that counts and labels up to two ships "
                        "(estimates.csv gets a ship column)")
    t.add_argument("--out", default="shipsense-track", help="output directory (default: %(default)s)")
    t.add_argument("--seed", type=SEED, default=None, help="seed of the simulated passage")
    t.add_argument("--random", action="store_true", help="simulate a random passage from the [prior]")
    t.set_defaults(func=cmd_track)

    c = sub.add_parser("check", parents=[limits],
                       help="observability and ambiguity verdict of arrays (exit 0/3/4; a CI gate) and the "
                       "separation at which they tell two ships apart",
                       description="Exit codes (the worst over the files): 0 observable, 3 ambiguous, 4 degenerate, "
                       "2 bad input.")
    c.add_argument("layout", metavar="SCENARIO_OR_LAYOUT", nargs="+",
                   help="shipped scenario names or TOML files (several: one verdict each)")
    c.add_argument("--json", action="store_true", help="print {verdict, min_chi2, pairs, fim_rank, fim_condition, "
                   "resolvability} (a list of them, with 'layout', for several files)")
    c.add_argument("--junit", default=None, metavar="FILE.xml",
                   help="also write a JUnit XML report: one test case per layout")
    c.add_argument("--passages", type=whole_flag(1, PASSAGES_MAX), default=8,
                   help="passages drawn from the [prior] (default 8)")
    c.add_argument("--seed", type=SEED, default=0)
    c.set_defaults(func=cmd_check)

    g = sub.add_parser("design", parents=[limits], help="place k sensors (convex relaxation, rounding, ambiguity cuts)")
    g.add_argument("scenario", help="a shipped scenario name or a TOML file (its first sensor is the template)")
    g.add_argument("--k", type=whole_flag(1, 1000), required=True, help="number of sensors to place")
    g.add_argument("--criterion", default="D",
                   help="D, A or E (default D), or resolvability: the layout that best tells two ships apart at "
                        "--separation")
    g.add_argument("--separation", type=float, default=None, metavar="METRES",
                   help="with --criterion resolvability: the two ships' separation the layouts are valued at "
                        "(default 20)")
    g.add_argument("--candidates", default=None, help="candidate positions: CSV x,y[,z] or TOML [candidates] "
                   "polygon, spacing, z, exclusions, min_spacing (default: a grid around the array)")
    g.add_argument("--out", default="shipsense-design",
                   help="report folder: layout.toml, design.json, design.png, bounds.png (default: %(default)s)")
    g.add_argument("--passages", type=whole_flag(1, PASSAGES_MAX), default=8,
                   help="prior passages to average over (default 8)")
    g.add_argument("--seed", type=SEED, default=0)
    g.add_argument("--budget", type=float, default=None,
                   help="total cost allowed, with a 'cost' column in the candidate CSV")
    g.add_argument("--no-cuts", action="store_true", help="skip the ambiguity cuts")
    g.add_argument("--solver", default="auto",
                   help="relaxation solver: auto (CLARABEL up to 800 candidates, else first-order), clarabel "
                        "(interior point; falls back to first-order if it fails) or first-order (projected "
                        "gradient, Frank-Wolfe with cuts or a budget); default auto")
    g.add_argument("--bb-work", type=whole_flag(0, 10**12), default=None,
                   help="work limit of the search over subsets that tightens the bound for few sensors (D: the exact "
                        "search for k <= 4, subset values computed, default 20,000,000; A, E: the branch and bound "
                        "for k <= 3, node bounds, default 2,000; 0: off)")
    g.add_argument("--bb-seconds", type=float, default=120.0,
                   help="time guard of that search: it stops on its work, this only keeps a slow machine from "
                        "waiting without end, and the report says when it fired (default 120; inf: none)")
    g.add_argument("--prior-floor", type=float, default=None,
                   help="floor on the scaled prior information (a regulariser; default: none, the scenario's "
                        "prior covariance as it is)")
    g.set_defaults(func=cmd_design)

    tr = sub.add_parser("train", parents=[limits],
                        help="train a sensor-scheduling (PPO) or placement (MaskablePPO) agent (needs the rl extra)")
    tr.add_argument("task", choices=["placement", "scheduling"])
    tr.add_argument("--timesteps", type=whole_flag(1, TIMESTEPS_MAX), default=None,
                    help="environment steps (default: 30000 for scheduling, 20000 for placement, each after 30000 "
                         "steps of imitation)")
    tr.add_argument("--env", default=None, metavar="ID",
                    help="environment id (default: shipsense/ArrayDesign-v1 for placement, shipsense/Passage-v1 for "
                         "scheduling)")
    tr.add_argument("--env-kwargs", default=None, metavar="JSON", help="the environment's arguments, a JSON object")
    tr.add_argument("--n-envs", type=whole_flag(1, 256), default=8, help="parallel environments (default: %(default)s)")
    tr.add_argument("--eval-every", type=whole_flag(1, TIMESTEPS_MAX), default=None, metavar="STEPS",
                    help="held-out evaluation every this many steps (default: a tenth of --timesteps)")
    tr.add_argument("--eval-episodes", type=whole_flag(1, 100_000), default=20,
                    help="held-out episodes per evaluation (default: %(default)s)")
    tr.add_argument("--shaping", type=float, default=None, metavar="COEF",
                    help="weight of potential-based reward shaping with the environment's potential (Passage-v1: "
                         "the observer's position information); the optimal policies do not change "
                         "(default: 1 where the environment declares a potential, else 0)")
    tr.add_argument("--imitate", default=None, metavar="BASELINE",
                    help="clone this baseline by behaviour cloning, then train (Maskable)PPO from the clone "
                         "(Passage environments also the planners rollout and hindsight; 'none': from "
                         "scratch; default: greedy where the environment offers it)")
    tr.add_argument("--imitation-steps", type=whole_flag(64, TIMESTEPS_MAX), default=30_000, metavar="STEPS",
                    help="environment steps of the baseline that --imitate clones (default: %(default)s)")
    tr.add_argument("--out", default=None, help="output directory (default: results/train-TASK)")
    tr.add_argument("--seed", type=SEED, default=0)
    tr.set_defaults(func=cmd_train)

    ev = sub.add_parser("evaluate", parents=[limits],
                        help="evaluate a baseline or a trained model on seeded episodes of an environment",
                        description="Mean return +- standard error and the environment's task metrics over "
                        "episodes reset with seeds S, S+1, ...")
    ev.add_argument("env_id", metavar="ENV_ID", help="e.g. shipsense/ArrayDesign-v1")
    ev.add_argument("--policy", required=True, metavar="NAME|PATH.zip",
                    help="a baseline the environment offers (random, round-robin, greedy, convex; Passage "
                         "environments also greedy-threshold, rollout and the offline reference hindsight) or a "
                         "stable-baselines3 model file")
    ev.add_argument("--policy-kwargs", default=None, metavar="JSON",
                    help="a planning baseline's options, a JSON object: greedy-threshold {\"threshold\": nats} "
                         "(default: fitted on training seeds), rollout {\"horizon\": 8, \"samples\": 32}, "
                         "hindsight {\"beam\": 256}")
    ev.add_argument("--episodes", type=whole_flag(1, 10**6), default=50, help="episodes (default: %(default)s)")
    ev.add_argument("--seed", type=whole_flag(0, 2**31 - 1), default=2_000_000,
                    help="seed of the first episode (default: %(default)s, away from training's seeds)")
    ev.add_argument("--env-kwargs", default=None, metavar="JSON", help="the environment's arguments, a JSON object")
    ev.add_argument("--json", action="store_true", help="print the result as JSON")
    ev.set_defaults(func=cmd_evaluate)

    w = sub.add_parser("sweep", help="a layout study: layouts x site conditions x passages, on Dask, resumable",
                       description="Run the cells of SWEEP.toml (layouts x site conditions) in chunks of passages "
                       "on a local Dask cluster (or --scheduler), writing each finished chunk to DIR; rerunning "
                       "skips finished chunks.  `shipsense sweep --example` prints an example sweep file.")
    w.add_argument("sweep", nargs="?", metavar="SWEEP.toml", help="the sweep file")
    w.add_argument("--out", metavar="DIR", help="results folder (resumed if it holds this sweep's results)")
    w.add_argument("--workers", type=whole_flag(0, 1024), default=None,
                   help="local Dask workers, one thread each (default: the cores; 0 runs serially in-process)")
    w.add_argument("--scheduler", default=None, metavar="ADDRESS", help="an existing Dask scheduler, tcp://host:8786")
    w.add_argument("--restart", action="store_true",
                   help="start afresh, discarding the results found in DIR (this sweep's or another's)")
    w.add_argument("--csv", action="store_true", help="also write results.csv")
    w.add_argument("--quiet", action="store_true", help="no progress bar or log lines")
    w.add_argument("--example", action="store_true", help="print an example sweep file (about 100 cells) and exit")
    w.add_argument("--report", default=None, metavar="DIR", help="re-draw the plots of a finished sweep in DIR")
    w.set_defaults(func=cmd_sweep)

    r = sub.add_parser("reproduce", parents=[limits],
                       help="reproduce the reference experiments of S0, S1, S2, the wide-prior study, "
                       "or all of them")
    r.add_argument("name", metavar="S0|S1|S2|wide|all")
    r.add_argument("--runs", type=whole_flag(2, RUNS_MAX), default=None,
                   help="Monte Carlo runs (default: 200 for S0, 100 for S1 and S2, 500 passages per family for wide)")
    r.add_argument("--out", default=None, help="output directory (default: results/NAME; all: results)")
    r.add_argument("--seed", type=SEED, default=0)
    r.add_argument("--workers", type=whole_flag(0, 1024), default=None,
                   help="run on a local Dask cluster of N processes (default: the cores for wide and all, this "
                        "process for one of S0, S1, S2; 0: this process); finished studies and wide's chunks are "
                        "skipped when rerun")
    r.add_argument("--scheduler", default=None, metavar="ADDRESS", help="an existing Dask scheduler, tcp://host:8786")
    r.add_argument("--restart", action="store_true",
                   help="start afresh, discarding the results found in OUT (finished studies, wide's chunks; this "
                        "run's or another's)")
    r.set_defaults(func=cmd_reproduce)
    return p
