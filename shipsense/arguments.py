"""Checking arguments: one checker for the command line's flags, the environments' constructors and the API's
numbers, in the scenario file's words (``NAME: must be ..., got ...``; the scenario's and the tracker options'
fields are checked by their pydantic models, :mod:`shipsense.config`, whose messages say the same)."""

from __future__ import annotations

import math
import numbers

from shipsense.errors import ShipsenseError


def _range(lo, hi, integer, lo_open):
    def text(x):
        return str(int(x)) if integer and float(x).is_integer() else f"{x:g}"

    kind = "a whole number" if integer else "a number"
    return f"{kind} in {'(' if lo_open else '['}{text(lo)}, {text(hi)}]"


def number(name, value, lo, hi, *, integer=False, lo_open=False):
    """``value`` as a float (an int with ``integer``) in ``[lo, hi]`` (``lo_open``: ``(lo, hi]``); else a
    :class:`~shipsense.errors.ShipsenseError` (a ``ValueError``) naming ``name``, the range and what was given (a
    string, NaN, a fractional count, a boolean...)."""
    ok_type = isinstance(value, numbers.Integral) if integer else isinstance(value, numbers.Real)
    if isinstance(value, bool) or not ok_type:
        raise ShipsenseError(f"{name}: expected {'a whole number' if integer else 'a number'}, got "
                             f"{type(value).__name__} {value!r}")
    v = int(value) if integer else float(value)
    if not math.isfinite(v) or not (lo < v if lo_open else lo <= v) or not v <= hi:
        raise ShipsenseError(f"{name}: must be {_range(lo, hi, integer, lo_open)}, got {value!r}")
    return v


def whole_flag(lo, hi):
    """An ``argparse`` type: a flag's text as an integer in ``[lo, hi]`` (checked by :func:`number`), else one line
    that argparse prefixes with the flag's name (exit 2)."""
    import argparse

    def parse(text):
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
        try:
            return number("value", value, lo, hi, integer=True)
        except ShipsenseError as err:
            raise argparse.ArgumentTypeError(str(err).removeprefix("value: ")) from None

    parse.__name__ = "integer"
    return parse
