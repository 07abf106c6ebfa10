"""Tabulate a real RGL measurement (``*.bsdf``, read by Mitsuba's ``measured`` plugin) onto the
MERL grid, giving a MERL-format table of measured data (docs/design.md sections 3 and 9).

    python -m nbrdf_mitsuba.tabulate_rgl IN.bsdf -o OUT.binary [--phi-fold reciprocal|mirror]

Every cell is evaluated at its centre (continuous index i + 0.5, ``phi_h = 0``) in one vectorised
call; cells whose centre puts the light or the view at or below the horizon have no reflectance
and are stored as -1 (not measured), like the MERL files.

What Mitsuba's ``measured`` BSDF returns is ``e(wi, wo) = f_r cos(theta_wo)`` (the light is
``wo``), and two properties of it decide how a cell's ``f_r`` is estimated:

* it is **not reciprocal**: ``e(v, l) / l.z`` and ``e(l, v) / v.z`` differ by a few percent
  (paper, paints) to tens of percent (the colour-changing ``cc_*`` paints), and near the horizon
  ``e`` does not vanish with the cosine, so ``e / l.z`` grows without bound (1e4 to 1e7 per
  steradian in the first cells above the horizon); it is mirror-symmetric (``phi_d -> -phi_d``)
  to float precision, as any isotropic material;
* saturated colours give **negative RGB** components (out of gamut of the spectral
  measurement); a negative store would mark the whole cell as not measured, so they are
  clamped to 0 per channel, which is also what rendered images do.

``--phi-fold reciprocal`` (default; a MERL table any MERL reader understands): a cell stands for
both orderings of light and view, and holds ``(e(v, l) + e(l, v)) / (l.z + v.z)``, the
cosine-weighted mean of the two estimates ``e / cos`` (exact for reciprocal data, bounded near
the horizon).

``--phi-fold mirror``: the cells of ``phi_d`` in ``[0, pi)`` hold ``e(v, l) / l.z`` for the light
and view as they are, the other half being their mirror image, so the table keeps the
measurement's non-reciprocity. Readers must fold ``phi_d`` by mirror symmetry
(``nbrdf train|fit-phong|compare --phi-fold mirror``; the ``merl`` BSDF cannot). Where the
light's cosine is below ``GRAZING_COS`` (0.02, about the cosine step of one 1-degree cell at the
horizon) the reciprocal estimate is stored instead, since ``e / l.z`` there is unbounded and the
trilinear lookup would spread it to neighbouring directions with larger cosines.

A missing or unreadable input exits with status 2; a table that cannot be written, 1.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from . import _exit, llvm  # noqa: F401  (llvm sets DRJIT_LIBLLVM_PATH before Mitsuba starts its JIT)

N_THETA_H, N_THETA_D, N_PHI_D = 90, 90, 180
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
NOT_MEASURED = -1.0
PHI_FOLDS = ("reciprocal", "mirror")
GRAZING_COS = 0.02


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


def measured_eval_cos(measured, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """Mitsuba's ``eval`` (N, 3), ``f_r cos(theta_light)``, of a measured BSDF (a path or a
    loaded BSDF) with ``si.wi = view`` and ``wo = light``."""
    import drjit as dr
    import mitsuba as mi

    if isinstance(measured, (str, Path)):
        measured = mi.load_dict({"type": "measured", "filename": str(measured)})
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(view.T.astype(np.float32))
    value = measured.eval(mi.BSDFContext(), si, mi.Vector3f(light.T.astype(np.float32)))
    return np.array(value, dtype=np.float64).reshape(3, -1).T


def evaluate_measured(path: Path, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """``f_r`` (N, 3) of a measured BSDF through Mitsuba: its ``eval`` divided by the light's
    cosine (unbounded near the horizon, see the module notes)."""
    cos_light = np.maximum(light[:, 2], 1e-12)
    return measured_eval_cos(path, light, view) / cos_light[:, None]


def cell_reflectance(e_lv: np.ndarray, e_vl: np.ndarray, cos_light: np.ndarray, cos_view: np.ndarray,
                     phi_fold: str = "reciprocal") -> np.ndarray:
    """``f_r`` (N, 3) of each cell from ``e_lv = e(wi=view, wo=light)`` and ``e_vl = e(wi=light,
    wo=view)`` (both ``f_r cos(wo)``, negatives already clamped) and the two cosines."""
    if phi_fold not in PHI_FOLDS:
        raise ValueError(f"unknown phi fold '{phi_fold}' (expected one of: {', '.join(PHI_FOLDS)})")
    cl, cv = cos_light[:, None], cos_view[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        reciprocal = (e_lv + e_vl) / (cl + cv)
        if phi_fold == "reciprocal":
            return reciprocal
        return np.where(cl >= GRAZING_COS, e_lv / np.maximum(cl, GRAZING_COS), reciprocal)


def tabulate(path: Path, variant: str, phi_fold: str = "reciprocal") -> np.ndarray:
    """Stored (scaled, channel-major) values of the table."""
    import mitsuba as mi

    mi.set_variant(variant)
    measured = mi.load_dict({"type": "measured", "filename": str(path)})
    light, view = cell_centre_directions()
    below = (light[:, 2] <= 0) | (view[:, 2] <= 0)
    cos_light, cos_view = np.maximum(light[:, 2], 0.0), np.maximum(view[:, 2], 0.0)

    def e(wo, wi):
        value = measured_eval_cos(measured, wo, wi)
        return np.maximum(np.nan_to_num(value, nan=0.0, posinf=0.0, neginf=0.0), 0.0)

    e_lv, e_vl = e(light, view), e(view, light)
    stored = cell_reflectance(e_lv, e_vl, cos_light, cos_view, phi_fold) / SCALE[None, :]
    stored[below] = NOT_MEASURED
    stored[~np.all(np.isfinite(stored), axis=1)] = NOT_MEASURED
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
    parser.add_argument("--phi-fold", choices=PHI_FOLDS, default="reciprocal",
                        help="reciprocal: a standard MERL table (both orderings of light and view "
                             "averaged); mirror: keeps the measurement's non-reciprocity, for "
                             "`nbrdf train --phi-fold mirror` (default: %(default)s)")
    args = parser.parse_args(argv)
    if not args.input.is_file():
        print(f"error: {args.input}: no such file", file=sys.stderr)
        return _exit.USAGE
    output = args.output or args.input.with_suffix(".binary")
    start = time.perf_counter()
    try:
        stored = tabulate(args.input, args.variant, args.phi_fold)
    except Exception as error:  # Mitsuba reports malformed files (and unknown variants) as plain exceptions
        print(f"error: {args.input}: {error}", file=sys.stderr)
        return _exit.USAGE
    try:
        write_merl(output, stored)
    except OSError as error:
        print(f"error: {output}: cannot write the table: {error.strerror or error}", file=sys.stderr)
        return _exit.FAILED
    invalid = int(np.sum(stored[0] < 0))
    print(f"{output}: {stored.shape[1]} cells ({invalid} not measured, phi_d folded by {args.phi_fold}) "
          f"in {time.perf_counter() - start:.1f} s")
    return _exit.SUCCESS


if __name__ == "__main__":
    sys.exit(main())
