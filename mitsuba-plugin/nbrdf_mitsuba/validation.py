"""What the ``nbrdf`` and ``merl`` BSDFs refuse, said in the user's terms: sampling parameters
out of range, files that are special, of the other plugin's format, or not a table at all."""

from __future__ import annotations

import os
import stat

import numpy as np

from .jit.merl import N_PHI_D, N_THETA_D, N_THETA_H
from .jit.sampling import MAX_EXPONENT

#: How far above 1 two float32 lobe weights may sum (``sampling/two_lobe.rs``, same name): 1 + ulp.
WEIGHT_SUM_TOLERANCE = 1e-6
# The MERL format: three little-endian int32 dimensions, then 3 * 90 * 90 * 180 float64.
MERL_HEADER = np.array([N_THETA_H, N_THETA_D, N_PHI_D], dtype="<i4").tobytes()


def non_finite_name(value) -> str:
    return "NaN" if np.isnan(value) else ("+inf" if value > 0 else "-inf")


def sampling_problem(exponent: float, weight: float, second=None, two_lobe: bool = False,
                     second_exponent: str = "exponent2") -> str | None:
    """Why (exponent, specular_weight) and the optional second lobe (``second_exponent``:
    exponent2, or exponent_v of the anisotropic lobe; specular_weight2) cannot be used, naming
    NaN where NaN is the problem; the weights' sum matters only to ``two_lobe`` sampling."""
    lobes = [("exponent", "specular_weight", exponent, weight)]
    if second is not None:
        lobes.append((second_exponent, "specular_weight2", *second))
    for exponent_name, weight_name, n, w in lobes:
        if not np.isfinite(n):
            return f"{exponent_name} is {non_finite_name(n)} (must be finite, in [0, {MAX_EXPONENT:g}])"
        if n < 0:
            return f"{exponent_name} {n:g} is negative (must be in [0, {MAX_EXPONENT:g}])"
        if n > MAX_EXPONENT:
            return (f"{exponent_name} {n:g} is above the maximum {MAX_EXPONENT:g} (MAX_EXPONENT: "
                    "sharper lobes are not resolved by float32 directions)")
        if not np.isfinite(w):
            return f"{weight_name} is {non_finite_name(w)} (must be in [0, 1])"
        if not 0.0 <= w <= 1.0:
            return f"{weight_name} {w:g} is outside [0, 1]"
    if two_lobe and second is not None and weight + second[1] > 1.0 + WEIGHT_SUM_TOLERANCE:
        return (f"specular_weight {weight:g} + specular_weight2 {second[1]:g} is above 1 (the "
                "cosine lobe takes 1 - specular_weight - specular_weight2)")
    return None


def special_file_problem(path: str) -> str | None:
    """Why ``path`` cannot be read as a BSDF without blocking (a FIFO would block, /dev/zero
    never ends), judged from its metadata alone."""
    try:
        info = os.stat(path)
    except OSError:
        return None  # the library reports missing and unreadable files
    if not stat.S_ISREG(info.st_mode):
        return "not a regular file (a directory, FIFO or device cannot be read as a BSDF)"
    return None


def format_problem(path: str, plugin: str) -> str | None:
    """Why the library could not load ``path`` for ``plugin`` (or loaded the other plugin's
    kind), in the user's terms: the other plugin's format, binary data, a table's values."""
    try:
        with open(path, "rb") as file:
            head = file.read(64)
    except OSError:
        return None  # the library's I/O error says it
    is_merl = head[:12] == MERL_HEADER
    is_json = head.lstrip()[:1] in (b"{", b"[")
    if plugin == "nbrdf" and is_merl:
        return ("this is a MERL table; the nbrdf BSDF reads *.nbrdf.json networks "
                '(use the merl BSDF: "type": "merl")')
    if plugin == "nbrdf" and b"\0" in head:
        return ("this is binary data, not an *.nbrdf.json network (JSON text); MERL tables go to "
                'the merl BSDF ("type": "merl")')
    if plugin == "merl" and is_json:
        return ("this is a JSON file (an *.nbrdf.json network?); the merl BSDF reads MERL .binary "
                'tables (use the nbrdf BSDF for networks: "type": "nbrdf")')
    if plugin == "merl" and is_merl:
        return None  # the library names the bad size or value (nbrdf-core merl/io.rs)
    if plugin == "merl":
        # The library reads a file without a table's header as a network, and would say why
        # it is not one.
        return "not a MERL table (a .binary table starts with the resolutions 90, 90, 180 as int32)"
    return None


def strip_function(error: Exception) -> str:
    """A library message without its leading ``nbrdf_xxx: `` function name."""
    message = str(error)
    head, sep, tail = message.partition(": ")
    return tail if sep and head.startswith("nbrdf_") and " " not in head else message
