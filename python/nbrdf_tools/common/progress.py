"""Progress bars of the scripts (tqdm), switched off for logs by ``--no-progress``."""

from __future__ import annotations

from tqdm import tqdm

_enabled = True


def set_enabled(enabled: bool) -> None:
    global _enabled
    _enabled = enabled


def enabled() -> bool:
    return _enabled


def bar(iterable=None, **kwargs) -> tqdm:
    """``tqdm(iterable, **kwargs)``, disabled when progress is off."""
    kwargs["disable"] = kwargs.get("disable", False) or not _enabled
    return tqdm(iterable, **kwargs)


def log(message: str) -> None:
    """Prints a line without breaking a progress bar."""
    tqdm.write(message)
