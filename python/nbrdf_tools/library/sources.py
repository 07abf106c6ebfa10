"""The materials of a library: which files are sources, what kind each is, and its name.

A source is a MERL-format table (``.binary``), an RGL measurement (``.bsdf``) or a Mitsuba BSDF
description (a ``mi.load_dict`` dictionary ``.json`` or a scene ``.xml`` holding one BSDF, which
the distiller reads). A folder stands for the sources under it (recursively, by suffix; trained
networks, ``*.nbrdf.json``, are not sources). A material's name is its file name without the
suffix; two sources of one name are both refused, so that no output silently replaces another.
"""

from __future__ import annotations

import fnmatch
from dataclasses import dataclass
from pathlib import Path

KINDS = {".binary": "merl", ".bsdf": "rgl", ".json": "mitsuba", ".xml": "mitsuba"}
# Files a folder may hold beside its sources that are never sources themselves.
NOT_SOURCES = (".nbrdf.json",)


@dataclass(frozen=True)
class Source:
    name: str
    path: str  # absolute, as the workers read it
    kind: str  # "merl", "rgl" or "mitsuba"


@dataclass(frozen=True)
class Refused:
    """A file named as a source that cannot be one (its row is a failure with this reason)."""
    name: str
    path: str
    error: str


def kind_of(path: Path) -> str | None:
    name = path.name.lower()
    if any(name.endswith(s) for s in NOT_SOURCES):
        return None
    return KINDS.get(path.suffix.lower())


def material_name(path: Path) -> str:
    return path.name[: -len(path.suffix)] if path.suffix else path.name


def _folder_sources(folder: Path, skip: Path | None) -> list[Path]:
    found = []
    for path in sorted(folder.rglob("*")):
        if skip is not None and path.resolve().is_relative_to(skip):
            continue
        if path.is_file() and not path.name.startswith(".") and kind_of(path) is not None:
            found.append(path)
    return found


def discover(paths: list[Path], out: Path | None = None) -> tuple[list[Source], list[Refused]]:
    """The sources named by ``paths`` (files and folders; the output folder ``out`` is skipped
    when it lies inside one), and the files refused: an explicit file of no known kind, and
    every source whose name another source has too. Raises FileNotFoundError for a path that
    does not exist."""
    skip = out.resolve() if out is not None else None
    files: list[Path] = []
    refused: list[Refused] = []
    for given in paths:
        if given.is_dir():
            files += _folder_sources(given, skip)
        elif given.is_file():
            if kind_of(given) is None:
                refused.append(Refused(material_name(given), str(given.resolve()),
                                       f"{given}: not a source (expected .binary, .bsdf, .json or .xml)"))
            else:
                files.append(given)
        else:
            raise FileNotFoundError(f"{given}: no such file or folder")
    unique: dict[str, Path] = {}
    for path in files:
        unique.setdefault(str(path.resolve()), path)
    by_name: dict[str, list[Path]] = {}
    for path in unique.values():
        by_name.setdefault(material_name(path), []).append(path)
    sources = []
    for name, group in sorted(by_name.items()):
        if len(group) > 1:
            listed = ", ".join(str(p) for p in group)
            refused += [Refused(name, str(p.resolve()), f"{len(group)} sources are named {name}: {listed}")
                        for p in group]
        else:
            path = group[0]
            sources.append(Source(name=name, path=str(path.resolve()), kind=kind_of(path)))
    return sources, refused


def select(names: list[str], patterns: list[str] | None) -> set[str]:
    """The names matching any of the shell patterns (all names without patterns)."""
    if not patterns:
        return set(names)
    return {n for n in names if any(fnmatch.fnmatchcase(n, p) for p in patterns)}
