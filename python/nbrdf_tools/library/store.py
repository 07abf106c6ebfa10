"""The library's folder: each material's outputs, keyed by what made them, written atomically.

    OUT/materials/NAME/NAME.nbrdf.json   the network with its fitted sampling
    OUT/materials/NAME/NAME.png          the thumbnail: the source's sphere beside the network's
    OUT/materials/NAME/row.json          the fidelity row, written last

A file is written to a temporary name beside it (``.nbrdf-tmp-*``), flushed to disk and renamed
over the final name, so a reader (or an interrupted run) sees the old file or the new one, never
part of one. ``row.json`` goes last and records the key and the SHA-256 of the files it belongs
to: a material counts as done only when its row has the current key and its files match. A run
starts by deleting the temporary files an interrupted run left.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

TEMP_PREFIX = ".nbrdf-tmp-"
ROW = "row.json"
# mkstemp makes its files private (0600); the outputs get what a plain open() would give them.
_UMASK = os.umask(0o022)
os.umask(_UMASK)


def sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 22), b""):
            digest.update(block)
    return digest.hexdigest()


def write_atomic(path: Path, data: bytes | str) -> Path:
    """Writes ``data`` to ``path`` through a temporary file in the same folder and a rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(data, str):
        data = data.encode("utf-8")
    fd, temp = tempfile.mkstemp(prefix=TEMP_PREFIX, dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(temp, 0o666 & ~_UMASK)
        os.replace(temp, path)
    except BaseException:
        Path(temp).unlink(missing_ok=True)
        raise
    return path


def remove_temporaries(out: Path) -> int:
    """Deletes the temporary files under ``out`` (left by an interrupted run); their number."""
    count = 0
    if Path(out).is_dir():
        for path in Path(out).rglob(TEMP_PREFIX + "*"):
            if path.is_file():
                path.unlink(missing_ok=True)
                count += 1
    return count


class Store:
    def __init__(self, out: Path):
        self.out = Path(out)

    def folder(self, name: str) -> Path:
        return self.out / "materials" / name

    def files(self, name: str) -> dict[str, Path]:
        folder = self.folder(name)
        return {"network": folder / f"{name}.nbrdf.json", "thumbnail": folder / f"{name}.png"}

    def row(self, name: str) -> dict | None:
        try:
            return json.loads((self.folder(name) / ROW).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None

    def done(self, name: str, key: str) -> dict | None:
        """The stored row when it is a success made with ``key`` and its files are intact."""
        row = self.row(name)
        if not row or row.get("status") != "ok" or row.get("key") != key:
            return None
        for kind, path in self.files(name).items():
            try:
                if file_sha256(path) != row.get("sha256", {}).get(kind):
                    return None
            except OSError:
                return None
        return row

    def put(self, result: dict) -> dict:
        """Writes a worker's result: its files (a success), then its row, which it returns
        without the bytes. A failure removes the outputs of an earlier success, so that the
        folder says what the index says."""
        result = dict(result)
        data = result.pop("files", None) or {}
        name = result["name"]
        paths = self.files(name)
        if result.get("status") == "ok":
            result["sha256"] = {}
            for kind, path in paths.items():
                write_atomic(path, data[kind])
                result["sha256"][kind] = sha256(data[kind])
            result["files"] = {kind: str(path.relative_to(self.out)) for kind, path in paths.items()}
        else:
            for path in paths.values():
                path.unlink(missing_ok=True)
        write_atomic(self.folder(name) / ROW, json.dumps(result, indent=1) + "\n")
        return result
