"""Tabulate a real RGL measurement (``*.bsdf``, read by Mitsuba's ``measured`` plugin) onto the
MERL grid, giving a MERL-format table of measured data (DESIGN.md sections 3 and 9).

    python -m nbrdf_mitsuba.tabulate_rgl IN.bsdf -o OUT.binary [--variant llvm_ad_rgb]

Every cell is evaluated at its centre (continuous index i + 0.5, ``phi_h = 0``) in one vectorised
call; cells whose centre puts the light or the view at or below the horizon have no reflectance
and are stored as -1 (not measured), like the MERL files.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from . import llvm  # noqa: F401  (sets DRJIT_LIBLLVM_PATH before Mitsuba starts its JIT)

N_THETA_H, N_THETA_D, N_PHI_D = 90, 90, 180
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
NOT_MEASURED = -1.0


def cell_centre_directions() -> tuple[np.ndarray, np.ndarray]:
    """Light and view directions ``(N, 3)`` at the centres of all cells, in file order."""
    i_th, i_td, i_pd = np.meshgrid(
        np.arange(N_THETA_H), np.arange(N_THETA_D), np.arange(N_PHI_D), indexing="ij"
    )
    theta_h = ((i_th.ravel() + 0.5) / N_THETA_H) ** 2 * (np.pi / 2)
    theta_d = (i_td.ravel() + 0.5) / N_THETA_D * (np.pi / 2)
    phi_d = (i_pd.ravel() + 0.5) / N_PHI_D * np.pi
    d = np.stack(
        [np.sin(theta_d) * np.cos(phi_d), np.sin(theta_d) * np.sin(phi_d), np.cos(theta_d)], axis=1
    )
    # l = R_y(theta_h) d with phi_h = 0, v = 2 (l . h) h - l
    ch, sh = np.cos(theta_h), np.sin(theta_h)
    light = np.stack([ch * d[:, 0] + sh * d[:, 2], d[:, 1], -sh * d[:, 0] + ch * d[:, 2]], axis=1)
    half = np.stack([sh, np.zeros_like(sh), ch], axis=1)
    view = 2.0 * np.sum(light * half, axis=1, keepdims=True) * half - light
    return light, view


def evaluate_measured(path: Path, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """``f_r`` (N, 3) of a measured BSDF through Mitsuba (its ``eval`` returns ``f_r cos``)."""
    import drjit as dr
    import mitsuba as mi

    bsdf = mi.load_dict({"type": "measured", "filename": str(path)})
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(view.T.astype(np.float32))
    ctx = mi.BSDFContext()
    value = bsdf.eval(ctx, si, mi.Vector3f(light.T.astype(np.float32)))
    f_cos = np.array(value, dtype=np.float64).reshape(3, -1).T
    cos_light = np.maximum(light[:, 2], 1e-12)
    return f_cos / cos_light[:, None]


def tabulate(path: Path, variant: str) -> np.ndarray:
    """Stored (scaled, channel-major) values of the table."""
    import mitsuba as mi

    mi.set_variant(variant)
    light, view = cell_centre_directions()
    below = (light[:, 2] <= 0) | (view[:, 2] <= 0)
    f = evaluate_measured(path, light, view)
    stored = f / SCALE[None, :]
    stored[below] = NOT_MEASURED
    stored[~np.isfinite(stored)] = NOT_MEASURED
    return np.ascontiguousarray(stored.T)


def write_merl(path: Path, stored: np.ndarray) -> None:
    header = np.array([N_THETA_H, N_THETA_D, N_PHI_D], dtype="<i4")
    with open(path, "wb") as f:
        f.write(header.tobytes())
        f.write(stored.astype("<f8").tobytes())


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m nbrdf_mitsuba.tabulate_rgl",
        description="Tabulate an RGL measured BSDF (.bsdf) onto the MERL grid (.binary).",
    )
    parser.add_argument("input", type=Path, help="RGL measurement, e.g. paper_white_rgb.bsdf")
    parser.add_argument("-o", "--output", type=Path, help="output table (default: INPUT with .binary)")
    parser.add_argument("--variant", default="llvm_ad_rgb", help="Mitsuba variant (scalar_rgb is very slow)")
    args = parser.parse_args(argv)
    if not args.input.is_file():
        print(f"error: {args.input}: no such file", file=sys.stderr)
        return 1
    output = args.output or args.input.with_suffix(".binary")
    start = time.perf_counter()
    try:
        stored = tabulate(args.input, args.variant)
    except Exception as error:  # Mitsuba reports malformed files as plain exceptions
        print(f"error: {args.input}: {error}", file=sys.stderr)
        return 1
    write_merl(output, stored)
    invalid = int(np.sum(stored[0] < 0))
    print(f"{output}: {stored.shape[1]} cells ({invalid} not measured) in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
