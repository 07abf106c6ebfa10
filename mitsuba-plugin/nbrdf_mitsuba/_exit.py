"""The exit statuses of every ``python -m nbrdf_mitsuba`` command (docs/hardening.md, "Exit
status of python -m nbrdf_mitsuba"). Each error is one line on stderr, ``error: ...``, never a
traceback."""

#: Done (also ``--help``).
SUCCESS = 0
#: The work itself failed: a render, a training or an estimate that diverged, an output that
#: could not be written once the work was done.
FAILED = 1
#: A usage or input error: a bad flag, a missing or invalid file, an invalid value (argparse's
#: own status for a bad flag).
USAGE = 2
