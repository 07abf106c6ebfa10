"""Cached high-sample-count renders (ground truths and converged references).

A render is stored as ``NAME.exr`` with a JSON sidecar ``NAME.json`` that records what it was
made from: the scene description, the content hashes of the input files (material tables,
networks, measured data, scene files), the settings (spp, resolution, integrator, ...) and the
code version (this package's scene code, the installed ``nbrdf_mitsuba`` plugin, Mitsuba and
Dr.Jit). The key is the SHA-256 of all of it; a render is reused only when the key matches, and
re-rendered (overwriting both files) whenever any input changes.
"""

from __future__ import annotations

import datetime
import hashlib
import json
import time
from pathlib import Path
from collections.abc import Callable

import numpy as np

from nbrdf_tools.common.render import read_exr, write_exr

HERE = Path(__file__).resolve().parent
# Our code whose changes invalidate cached renders (paths relative to this package).
CODE_FILES = ("ground_truth.py", "render.py", "scenes/veach.py", "scenes/kitchen.py")

_file_hashes: dict[tuple[str, int, int], str] = {}


def file_hash(path: Path) -> str:
    """SHA-256 of a file's content (memoised per path, size and modification time)."""
    path = Path(path).resolve()
    stat = path.stat()
    key = (str(path), stat.st_size, stat.st_mtime_ns)
    if key not in _file_hashes:
        digest = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 22), b""):
                digest.update(block)
        _file_hashes[key] = digest.hexdigest()
    return _file_hashes[key]


def code_version() -> dict[str, str]:
    """Versions and source hashes of everything that turns a scene into pixels."""
    import drjit as dr
    import mitsuba as mi
    import nbrdf_mitsuba

    plugin = Path(nbrdf_mitsuba.__file__).resolve().parent
    sources = sorted(plugin.rglob("*.py"))
    digest = hashlib.sha256()
    for source in sources:
        digest.update(source.relative_to(plugin).as_posix().encode())
        digest.update(source.read_bytes())
    ours = hashlib.sha256()
    for name in CODE_FILES:
        path = HERE / name
        if path.exists():
            ours.update(name.encode())
            ours.update(path.read_bytes())
    return {"mitsuba": mi.__version__, "drjit": dr.__version__, "nbrdf_mitsuba": nbrdf_mitsuba.__version__,
            "plugin_sources": digest.hexdigest()[:16], "scene_code": ours.hexdigest()[:16]}


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    if isinstance(value, np.generic):
        return value.item()
    return str(value)


def manifest(description, files, settings) -> dict:
    """What a cached render depends on (without the key)."""
    return {
        "description": _jsonable(description),
        "files": {str(Path(f)): file_hash(Path(f)) for f in files},
        "settings": _jsonable(settings),
        "code_version": code_version(),
    }


def manifest_key(document: dict) -> str:
    """SHA-256 of a manifest; input files count by content, not by where they lie."""
    keyed = dict(document)
    keyed["files"] = sorted(document["files"].values())
    return hashlib.sha256(json.dumps(keyed, sort_keys=True).encode()).hexdigest()


class RenderCache:
    """Folder of cached renders: ``get(name, description, files, settings, render)``."""

    def __init__(self, folder: Path, force: bool = False):
        self.folder = Path(folder)
        self.force = force
        self.hits = 0
        self.misses = 0

    def paths(self, name: str) -> tuple[Path, Path]:
        return self.folder / f"{name}.exr", self.folder / f"{name}.json"

    def lookup(self, name: str, key: str) -> np.ndarray | None:
        exr, sidecar = self.paths(name)
        if self.force or not exr.is_file() or not sidecar.is_file():
            return None
        try:
            stored = json.loads(sidecar.read_text())
        except (OSError, json.JSONDecodeError):
            return None
        if stored.get("key") != key:
            return None
        return read_exr(exr)

    def get(self, name: str, description, files, settings: dict, render: Callable[[], np.ndarray]) -> np.ndarray:
        """The cached render ``name`` if its inputs are unchanged, else ``render()`` (stored)."""
        document = manifest(description, files, settings)
        key = manifest_key(document)
        image = self.lookup(name, key)
        if image is not None:
            self.hits += 1
            return image
        self.misses += 1
        start = time.perf_counter()
        image = render()
        seconds = time.perf_counter() - start
        if not np.all(np.isfinite(image)):
            raise RuntimeError(f"reference render {name}: NaN or Inf in the image")
        exr, sidecar = self.paths(name)
        write_exr(exr, image)
        document.update(key=key, seconds=round(seconds, 3), exr=exr.name,
                        created=datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"))
        sidecar.write_text(json.dumps(document, indent=2, sort_keys=True) + "\n")
        # What the caller gets is what a later cache hit returns (EXR stores float32).
        return read_exr(exr)
