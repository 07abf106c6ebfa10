"""The estimate's errors: one line for the user, never a traceback."""


class EstimateError(Exception):
    """A user error: printed as one line, exit status 2."""
