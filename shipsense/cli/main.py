"""The command line's entry point: parse, run the command, turn errors into one line and an exit code."""

from __future__ import annotations

import sys

from shipsense.cli.common import EXIT_BAD_INPUT, EXIT_INTERNAL, QUIET
from shipsense.cli.parser import build_parser
from shipsense.errors import ShipsenseError


def _interrupted(err):
    """Whether ``err`` stands for an interruption: a KeyboardInterrupt in its chain of causes (a signal handler
    that raises while a compiled kernel runs surfaces as "SystemError: ... returned a result with an exception
    set", caused by the KeyboardInterrupt)."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return True
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return False


def main(argv=None) -> int:
    from shipsense.allocator import tune_allocator

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:   # a bad argument (exit 2, its message printed), --help or --version (0)
        return exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else EXIT_BAD_INPUT)
    tune_allocator()   # the command is its own process: reuse freed heap (see shipsense.allocator)
    import signal

    def terminated(signum, frame):   # a CI cancel or `timeout`: unwind like Ctrl-C, so staged outputs are removed
        raise KeyboardInterrupt

    import threading

    if threading.current_thread() is threading.main_thread() and signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        signal.signal(signal.SIGTERM, terminated)
    QUIET["on"] = bool(args.no_progress)
    try:
        return args.func(args)
    except (ShipsenseError, OSError) as err:   # input the user can fix: one line naming it
        print(f"shipsense {args.command}: error: {err}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"shipsense {args.command}: interrupted", file=sys.stderr)
        return 130
    except Exception as err:   # a bug, not the input: one line, the traceback on request
        if _interrupted(err):   # Ctrl-C or SIGTERM inside compiled code: numba wraps it in a SystemError
            print(f"shipsense {args.command}: interrupted", file=sys.stderr)
            return 130
        if args.debug:
            raise
        print(f"shipsense {args.command}: internal error: {type(err).__name__}: {err} "
              "(run with --debug for the traceback)", file=sys.stderr)
        return EXIT_INTERNAL
