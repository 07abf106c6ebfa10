"""Spectral RGL measurements (``*_spec.bsdf``) made from RGB ones, for tests and experiments: no
spectral measurement is at hand, and the format (Mitsuba's ``measured`` BSDF,
``src/bsdfs/measured.cpp``) differs from the RGB one only in its reflectance fields: instead of
``rgb`` (``[phi_i, theta_i, 3, n, n]``) a spectral file has ``wavelengths`` (float32, nm,
increasing) and ``spectra`` (``[phi_i, theta_i, len(wavelengths), n, n]``).

    python -m nbrdf_tools spectral-rgl IN_rgb.bsdf -o OUT_spec.bsdf [--wavelengths 360:1000:33]

Each cell's RGB value ``(r, g, b)`` becomes the spectrum ``r R(l) + g G(l) + b B(l)`` of three
smooth, positive, overlapping basis spectra (:func:`basis_spectra`, Gaussians at 610, 545 and
455 nm), sampled at the given wavelengths. The map is linear, so everything linear about the
measurement (its interpolation, its sRGB projection) can be predicted from the RGB file: the
tests compare the spectral file evaluated per wavelength with Mitsuba's ``measured`` in a
spectral variant, and its sRGB projection with a NumPy float64 integral of the RGB file's values
times the projected basis. The other fields (angles, NDF, VNDF, ...) are copied unchanged.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from pathlib import Path

import numpy as np

#: Centre and width (nm) of the smooth basis spectra standing for R, G and B.
BASIS = ((610.0, 45.0), (545.0, 40.0), (455.0, 35.0))


def basis_spectra(wavelengths) -> np.ndarray:
    """The three basis spectra at ``wavelengths`` (nm), shape ``(3, len(wavelengths))``."""
    w = np.asarray(wavelengths, np.float64)
    return np.stack([np.exp(-0.5 * ((w - centre) / width) ** 2) for centre, width in BASIS])


def parse_wavelengths(text: str) -> np.ndarray:
    """``FIRST:LAST:COUNT`` (evenly spaced) or a comma-separated list, in nm."""
    if ":" in text:
        first, last, count = text.split(":")
        return np.linspace(float(first), float(last), int(count))
    return np.array([float(v) for v in text.split(",")])


def read_tensor_file(path: Path) -> dict:
    """The fields of a tensor file as NumPy arrays (Mitsuba's own reader, its log silenced)."""
    from mitsuba.python import tensor_io

    with contextlib.redirect_stdout(io.StringIO()):
        return tensor_io.read(str(path))


def write_tensor_file(path: Path, fields: dict) -> Path:
    """Writes ``fields`` (name -> NumPy array) with Mitsuba's own writer."""
    from mitsuba.python import tensor_io

    with contextlib.redirect_stdout(io.StringIO()):
        tensor_io.write(str(path), **fields)
    return Path(path)


def spectral_fields(rgb_fields: dict, wavelengths) -> dict:
    """The fields of the spectral measurement made from an RGB one's (see the module docs)."""
    if "rgb" not in rgb_fields:
        raise ValueError("not an RGB measurement (no field 'rgb')")
    wavelengths = np.asarray(wavelengths, np.float32)
    basis = basis_spectra(wavelengths)
    rgb = rgb_fields["rgb"].astype(np.float64)
    spectra = np.einsum("ptcyx,cn->ptnyx", rgb, basis).astype(np.float32)
    fields = {k: v for k, v in rgb_fields.items() if k != "rgb"}
    fields["wavelengths"] = wavelengths
    fields["spectra"] = np.ascontiguousarray(spectra)
    return fields


def write_spectral(rgb_path: Path, out_path: Path, wavelengths) -> Path:
    """Writes the spectral measurement made from the RGB one at ``rgb_path``."""
    return write_tensor_file(out_path, spectral_fields(read_tensor_file(rgb_path), wavelengths))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools spectral-rgl", description=__doc__.split("\n\n")[0])
    parser.add_argument("source", type=Path, help="an RGB RGL measurement (*_rgb.bsdf)")
    parser.add_argument("-o", "--output", type=Path, required=True, help="the spectral file to write (*_spec.bsdf)")
    parser.add_argument("--wavelengths", default="360:1000:33", type=parse_wavelengths,
                        help="FIRST:LAST:COUNT or a comma-separated list, in nm (default 360:1000:33, "
                             "20 nm steps over the RGL database's range)")
    args = parser.parse_args(argv)
    try:
        write_spectral(args.source, args.output, args.wavelengths)
    except (OSError, ValueError, KeyError) as e:
        print(f"error: {args.source}: {e}", file=sys.stderr)
        return 1
    print(f"wrote {args.output} ({len(args.wavelengths)} wavelengths)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
