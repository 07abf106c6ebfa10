"""Where things are: the repository checkout, the shared data folder and the ``nbrdf`` CLI.

The shared data (MERL fits, the authors' Keras networks, RGL measurements, the kitchen scene) is
``$NBRDF_SHARED`` or, by default, ``../shared`` next to the repository. It is optional: what
needs it says what is missing through :func:`require_shared`.
"""

from __future__ import annotations

import os
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]
SCENES = REPO / "scenes"


class MissingDataError(FileNotFoundError):
    """A file or folder of the shared data (or another input) is absent; the message names it
    and how to provide it."""


def shared_dir() -> Path:
    """The shared data folder: ``$NBRDF_SHARED``, else ``<repo>/../shared`` (it may not exist)."""
    return Path(os.environ.get("NBRDF_SHARED") or REPO.parent / "shared")


def shared_path(*parts: str) -> Path:
    """A path inside the shared data folder (not checked)."""
    return shared_dir().joinpath(*parts)


def require_shared(*parts: str, what: str | None = None) -> Path:
    """``shared_path(*parts)``, or :class:`MissingDataError` naming what is missing when absent."""
    path = shared_path(*parts)
    if not path.exists():
        label = f"{what} " if what else ""
        raise MissingDataError(
            f"{label}{path} is missing: the shared data folder is {shared_dir()} "
            f"({'it exists' if shared_dir().is_dir() else 'absent'}); set NBRDF_SHARED to its location")
    return path


def default_cli() -> Path:
    """The nbrdf CLI: ``$NBRDF_CLI``, else ``release/nbrdf`` under ``$CARGO_TARGET_DIR`` (default
    this checkout's ``target/``)."""
    if os.environ.get("NBRDF_CLI"):
        return Path(os.environ["NBRDF_CLI"])
    target = Path(os.environ.get("CARGO_TARGET_DIR", REPO / "target"))
    if not target.is_absolute():
        target = REPO / target
    return target / "release" / ("nbrdf.exe" if os.name == "nt" else "nbrdf")


def default_out(*parts: str) -> Path:
    """The default output folder of a script: ``<repo>/out/...``."""
    return REPO.joinpath("out", *parts)
