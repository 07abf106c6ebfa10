"""A spatially varying material (file format version 4) evaluated through the C library's
``nbrdf_material_eval_uv``, the Rust reference, loaded with the repository's header
``nbrdf-ffi/include/nbrdf.h`` (the tests' own binding: the plugin does not load these files)."""

from __future__ import annotations

import os
from pathlib import Path

import cffi
import numpy as np

from nbrdf_mitsuba._native import library_path, strip_preprocessor

HEADER = Path(__file__).resolve().parents[1] / "nbrdf-ffi" / "include" / "nbrdf.h"

_ffi = cffi.FFI()
_ffi.cdef(strip_preprocessor(HEADER.read_text(encoding="utf-8")))
_lib = _ffi.dlopen(str(library_path()))


def _check(status: int) -> None:
    if status != 0:
        raise RuntimeError(_ffi.string(_lib.nbrdf_last_error()).decode())


class TexturedMaterial:
    """A material file loaded by ``nbrdf_material_load``."""

    def __init__(self, path: Path):
        out = _ffi.new("NbrdfMaterial **")
        _check(_lib.nbrdf_material_load(os.fsencode(path), out))
        self._ptr = _ffi.gc(out[0], _lib.nbrdf_material_free)

    def eval_cos(self, uv: np.ndarray, view: np.ndarray, light: np.ndarray) -> np.ndarray:
        """Planar (3, n) ``f_r cos(theta_light)`` at planar (2, n) ``uv`` and (3, n) directions."""
        uv, view, light = (np.ascontiguousarray(a, dtype=np.float32) for a in (uv, view, light))
        n = view.shape[1]
        out = np.zeros((3, n), np.float32)
        _check(_lib.nbrdf_material_eval_uv(self._ptr, *(_ffi.from_buffer("float[]", a) for a in (uv, view, light)),
                                           n, _ffi.from_buffer("float[]", out, require_writable=True), _ffi.NULL))
        return out.astype(np.float64)
