"""The project's error class: input the user can fix.

Every error a user can cause and correct (a scenario value, a recording row, a sweep file, a command-line
argument, work too large for the machine) is a :class:`ShipsenseError` whose message names the field, row or
flag and what was expected. The command line turns it into one line and exit code 2; anything else that
escapes a command is a bug (exit 1, with ``--debug`` for the traceback). It subclasses ``ValueError`` so that
callers of the Python API who catch ``ValueError`` keep working.
"""


class ShipsenseError(ValueError):
    """Input the user can fix; the message names what is wrong and what is accepted."""
