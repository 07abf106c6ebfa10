"""Loads the bundled ``libnbrdf_train`` (the trainer's C ABI, nbrdf-ffi/train) through cffi.

Only :mod:`nbrdf_mitsuba.distill` imports this module: rendering loads ``libnbrdf_ffi`` alone,
which carries no training code. The library is found as :mod:`nbrdf_mitsuba._native` finds its
own: ``$NBRDF_TRAIN_LIBRARY`` if set, else the copy bundled into the package by its build
(setup.py), with the header ``nbrdf_train.h`` beside it.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import cffi
import numpy as np

from ._native import strip_preprocessor

_HERE = Path(__file__).resolve().parent

#: ``NbrdfTrainSampling`` values by name.
SAMPLINGS = {"adaptive": 0, "uniform": 1}
#: ``NbrdfTrainFold`` values by name (the names of nbrdf-core's ``RglFold``).
FOLDS = {"as-measured": 0, "reciprocal-mean": 1}


class TrainError(RuntimeError):
    """A call into libnbrdf_train failed; ``status`` is the NbrdfTrainStatus code."""

    def __init__(self, message: str, status: int):
        super().__init__(message)
        self.status = status


def _library_name() -> str:
    if sys.platform == "win32":
        return "nbrdf_train.dll"
    if sys.platform == "darwin":
        return "libnbrdf_train.dylib"
    return "libnbrdf_train.so"


def library_path() -> Path:
    override = os.environ.get("NBRDF_TRAIN_LIBRARY")
    return Path(override) if override else _HERE / _library_name()


def header_path() -> Path:
    return _HERE / "nbrdf_train.h"


def _load():
    header, library = header_path(), library_path()
    for path, what in ((header, "C header"), (library, "training library")):
        if not path.is_file():
            raise ImportError(
                f"nbrdf_mitsuba: the {what} {path} is missing; reinstall the package "
                "(`pip install ./mitsuba-plugin`, which runs `cargo build --release -p nbrdf-train-ffi`) "
                "or point NBRDF_TRAIN_LIBRARY at a built libnbrdf_train"
            )
    ffi = cffi.FFI()
    ffi.cdef(strip_preprocessor(header.read_text(encoding="utf-8")))
    return ffi, ffi.dlopen(str(library))


ffi, lib = _load()


def last_error() -> str:
    return ffi.string(lib.nbrdf_train_last_error()).decode("utf-8", "replace")


def check(status: int) -> None:
    if status != 0:
        raise TrainError(last_error() or f"status {status}", status)


def default_config():
    """An ``NbrdfTrainConfig`` holding the trainer's defaults (those of ``nbrdf train``)."""
    config = ffi.new("NbrdfTrainConfig *")
    check(lib.nbrdf_train_config_default(config))
    return config


def for_anisotropy(config, anisotropic: bool, scale_samples: bool) -> None:
    """Makes ``config`` one for an isotropic or anisotropic network, in place; with
    ``scale_samples`` an anisotropic one gets the trainer's default factor times the samples."""
    check(lib.nbrdf_train_config_for_anisotropy(config, int(anisotropic), int(scale_samples)))


def sample_directions(config, fold: str = "as-measured") -> tuple[np.ndarray, np.ndarray, int]:
    """The trainer's planar (3, n) float32 ``view`` and ``light`` directions for ``config``
    (training pairs first) and how many of the last are for validation. ``fold`` is the one the
    values will train with (a :data:`FOLDS` name): for ``reciprocal-mean`` the pairs it would
    leave out (a cosine below 0.01) are replaced by the next candidates, so all of them train."""
    n_train, n_validation = ffi.new("size_t *"), ffi.new("size_t *")
    check(lib.nbrdf_train_sample_counts(config, n_train, n_validation))
    n = n_train[0] + n_validation[0]
    view, light = np.zeros((3, n), np.float32), np.zeros((3, n), np.float32)
    check(lib.nbrdf_train_directions(config, FOLDS[fold], n,
                                     ffi.from_buffer("float[]", view, require_writable=True),
                                     ffi.from_buffer("float[]", light, require_writable=True)))
    return view, light, int(n_validation[0])


def train_from_arrays(config, view: np.ndarray, light: np.ndarray, eval_cos: np.ndarray, n_validation: int,
                      name: str, source: str, details: dict | None = None, swapped_eval_cos: np.ndarray | None = None,
                      fold: str = "as-measured", on_epoch=None) -> str:
    """The JSON text of a network trained on planar (3, n) arrays (see ``nbrdf_train_from_arrays``
    in nbrdf_train.h); ``on_epoch(stats)`` gets an ``NbrdfEpochStats`` after every epoch."""
    arrays = [np.ascontiguousarray(a, dtype=np.float32) for a in (view, light, eval_cos)]
    n = arrays[0].shape[1]
    if any(a.shape != (3, n) for a in arrays):
        raise ValueError(f"expected planar (3, n) arrays, got shapes {[a.shape for a in arrays]}")
    swapped = ffi.NULL
    if swapped_eval_cos is not None:
        swapped_array = np.ascontiguousarray(swapped_eval_cos, dtype=np.float32)
        if swapped_array.shape != (3, n):
            raise ValueError(f"expected planar (3, {n}) swapped values, got shape {swapped_array.shape}")
        swapped = ffi.from_buffer("float[]", swapped_array)
    text = _call_for_json(lambda callback, out: lib.nbrdf_train_from_arrays(
        config, FOLDS[fold], *(ffi.from_buffer("float[]", a) for a in arrays), swapped, n, n_validation,
        name.encode(), source.encode(), _details_text(details), callback, ffi.NULL, out), on_epoch)
    return text


def train_spectral_from_arrays(config, view: np.ndarray, light: np.ndarray, wavelengths, eval_cos: np.ndarray,
                               n_validation: int, name: str, source: str, details: dict | None = None,
                               swapped_eval_cos: np.ndarray | None = None, fold: str = "as-measured",
                               on_epoch=None) -> str:
    """The JSON text of a spectral network (file format version 3) trained on planar (3, n)
    ``view`` and ``light`` and (m, n) ``eval_cos`` at the m ``wavelengths`` (nm): row j holds
    the values at wavelength j (see ``nbrdf_train_spectral_from_arrays`` in nbrdf_train.h)."""
    directions = [np.ascontiguousarray(a, dtype=np.float32) for a in (view, light)]
    n = directions[0].shape[1] if directions[0].ndim == 2 else -1
    if any(a.shape != (3, n) for a in directions):
        raise ValueError(f"expected planar (3, n) directions, got shapes {[a.shape for a in directions]}")
    lambdas = np.ascontiguousarray(np.asarray(wavelengths, dtype=np.float32).reshape(-1))
    m = len(lambdas)
    values = np.ascontiguousarray(eval_cos, dtype=np.float32)
    if values.shape != (m, n):
        raise ValueError(f"expected ({m}, {n}) values (wavelength-major), got shape {values.shape}")
    swapped = ffi.NULL
    if swapped_eval_cos is not None:
        swapped_array = np.ascontiguousarray(swapped_eval_cos, dtype=np.float32)
        if swapped_array.shape != (m, n):
            raise ValueError(f"expected ({m}, {n}) swapped values, got shape {swapped_array.shape}")
        swapped = ffi.from_buffer("float[]", swapped_array)
    # cffi refuses a zero-length buffer; the library refuses m = 0 itself, naming it.
    lambdas_ptr = ffi.from_buffer("float[]", lambdas) if m else ffi.new("float[1]")
    values_ptr = ffi.from_buffer("float[]", values) if values.size else ffi.new("float[1]")
    return _call_for_json(lambda callback, out: lib.nbrdf_train_spectral_from_arrays(
        config, FOLDS[fold], *(ffi.from_buffer("float[]", a) for a in directions), lambdas_ptr, m, values_ptr,
        swapped, n, n_validation, name.encode(), source.encode(), _details_text(details), callback, ffi.NULL, out),
        on_epoch)


def _details_text(details: dict | None):
    return json.dumps(details).encode() if details is not None else ffi.NULL


def _call_for_json(call, on_epoch) -> str:
    """Runs ``call(callback, out)`` (a trainer entry point writing a string to ``*out``) with
    ``on_epoch(stats)`` as the epoch callback; returns the string, freed in the library."""
    callback = ffi.NULL
    if on_epoch is not None:
        @ffi.callback("void(void *, const NbrdfEpochStats *)")
        def callback(_user, stats):
            on_epoch(stats)
    out = ffi.new("char **")
    check(call(callback, out))
    try:
        return ffi.string(out[0]).decode()
    finally:
        lib.nbrdf_train_string_free(out[0])


# -- spatially varying materials -----------------------------------------------------------------


def textured_default_config():
    """An ``NbrdfTexturedConfig`` holding the defaults of ``nbrdf_train_textured``."""
    config = ffi.new("NbrdfTexturedConfig *")
    check(lib.nbrdf_train_textured_config_default(config))
    return config


#: ``NbrdfBakeStage`` values by name.
BAKE_STAGES = {0: "encoded", 1: "clustering", 2: "fitting lobes"}


def train_textured(config, params: np.ndarray, view: np.ndarray, light: np.ndarray, eval_cos: np.ndarray,
                   image: np.ndarray, path, name: str, source: str, details: dict | None = None,
                   on_epoch=None, on_bake=None, wavelengths=None) -> None:
    """Trains a spatially varying material on n samples and writes it to ``path`` (its latent
    texture beside it; see ``nbrdf_train_textured`` in nbrdf_train.h): ``params`` (P, n), the
    parameters of each sample's texel; planar (3, n) ``view`` and ``light``; ``eval_cos`` planar
    (3, n) RGB, or with the m ``wavelengths`` (nm) of a spectral material (m, n), row j the
    values at wavelength j; ``image`` (height, width, P), the parameters at every texel centre,
    row 0 at v = 0. ``on_epoch(stats)`` gets an ``NbrdfEpochStats`` after every epoch,
    ``on_bake(stage, done, total)`` a :data:`BAKE_STAGES` name and counts as the baking
    proceeds."""
    directions = [np.ascontiguousarray(a, dtype=np.float32) for a in (view, light)]
    n = directions[0].shape[1]
    lambdas = np.ascontiguousarray([] if wavelengths is None else wavelengths, dtype=np.float32).reshape(-1)
    values = np.ascontiguousarray(eval_cos, dtype=np.float32)
    rows = 3 if wavelengths is None else lambdas.size
    if any(a.shape != (3, n) for a in directions) or values.shape != (rows, n):
        raise ValueError(f"expected planar (3, n) directions and ({rows}, n) values, got shapes "
                         f"{[a.shape for a in directions]} and {values.shape}")
    params = np.ascontiguousarray(params, dtype=np.float32)
    texels = np.ascontiguousarray(image, dtype=np.float32)
    if params.ndim != 2 or params.shape[1] != n or texels.ndim != 3 or texels.shape[2] != params.shape[0]:
        raise ValueError(f"expected (P, {n}) parameters and a (height, width, P) image, got shapes "
                         f"{params.shape} and {texels.shape}")
    epoch_callback, bake_callback = ffi.NULL, ffi.NULL
    if on_epoch is not None:
        @ffi.callback("void(void *, const NbrdfEpochStats *)")
        def epoch_callback(_user, stats):
            on_epoch(stats)
    if on_bake is not None:
        @ffi.callback("void(void *, const NbrdfBakeProgress *)")
        def bake_callback(_user, progress):
            on_bake(BAKE_STAGES.get(progress.stage, "baking"), progress.done, progress.total)

    def buffer(a):  # cffi refuses a zero-length buffer; the library names what is empty itself
        return ffi.from_buffer("float[]", a) if a.size else ffi.NULL

    height, width, parameters = texels.shape
    check(lib.nbrdf_train_textured(
        config, buffer(params), parameters, *(buffer(a) for a in directions), buffer(lambdas), lambdas.size,
        buffer(values), n, buffer(texels), width, height, os.fsencode(str(path)), name.encode(), source.encode(),
        _details_text(details), epoch_callback, bake_callback, ffi.NULL))
