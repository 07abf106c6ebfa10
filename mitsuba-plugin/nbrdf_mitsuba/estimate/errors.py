"""The estimate's errors: one line for the user, never a traceback."""

from .. import _exit


class EstimateError(Exception):
    """A usage or input error (a flag's value, the scene, the images, the autoencoder): printed
    as one line, exit status 2."""

    exit_status = _exit.USAGE


class EstimateFailed(EstimateError):
    """The estimate itself failed (it diverged, or its result could not be written): one line,
    exit status 1."""

    exit_status = _exit.FAILED
