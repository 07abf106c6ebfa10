"""How a spectral network should output its spectrum: the representation error of each candidate
on measured-like spectra, and what each costs in output weights (issue 31; the choice and its
reason are in docs/design.md, "Spectral networks").

    python -m nbrdf_tools spectral-basis --stored-only --out docs/results/spectral-basis.md  # from its data
    python -m nbrdf_tools spectral-basis [--out docs/results/spectral-basis.md] [--quick]

Candidates, each fitted per spectrum by least squares over 360-830 nm (Mitsuba's sampled range)
on a 2 nm grid, i.e. the best a network with that output layer could do:

* ``nodes K``: values at K evenly spaced wavelengths, linearly interpolated (K = 4 ... 16);
* ``B-spline K``: K coefficients of a clamped uniform cubic B-spline (a smooth linear basis);
* ``sigmoid-poly d``: ``scale * sigmoid(c_0 + c_1 x + ... + c_d x^d)``, ``x`` the wavelength
  mapped to [-1, 1] (Jakob and Hanika 2019's sRGB uplift model has d = 2 and no scale; BRDF
  values exceed 1, hence the scale): d + 2 outputs.

Spectra: the test files' (``nbrdf_tools.data.spectral_rgl``: the RGB values of the shared RGL
measurements' cells times three Gaussian basis spectra), smooth reflectance-like random spectra
(broad bumps and sigmoid edges), and the gold and copper conductors Mitsuba ships
(``roughconductor`` with ``material`` Au or Cu, ``f cos`` per wavelength at normal incidence and
at 60 degrees in ``scalar_spectral``). Errors, per spectrum ``s`` and fit ``g``: relative RMS
``rms(g - s) / rms(s)``, relative max ``max |g - s| / max |s|``, and the error of the linear sRGB
projection ``|P g - P s| / |P s|`` (Euclidean, under D65, :func:`srgb_weights`); the tables give
the mean and the worst over each set. Output weights: the RGB network is 6-21-21-3 (675
weights); K outputs make it ``675 - 66 + 22 K``. With ``--out`` the page is written and what it
reports stored in ``--data`` (``docs/results/data/spectral-basis.json``), from which
``--stored-only`` writes the page again without fitting anything.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

#: Mitsuba's ``MI_CIE_Y_NORMALIZATION`` (include/mitsuba/core/spectrum.h).
CIE_Y_NORMALIZATION = 1.0 / 106.7502593994140625
GRID = np.arange(360.0, 830.0 + 1e-9, 2.0)
HIDDEN = 21
RGB_WEIGHTS = 675


def output_weights(outputs: int) -> int:
    """Weights of the 6-21-21-K network: the RGB one's less its 3-output layer, plus K outputs."""
    return RGB_WEIGHTS - (HIDDEN + 1) * 3 + (HIDDEN + 1) * outputs


def _cie_tables():
    """Mitsuba's CIE 1931 and D65 tables at their 5 nm nodes, read through its Python API, and
    its XYZ -> linear sRGB matrix."""
    import mitsuba as mi

    # Read in scalar_rgb whatever the caller's variant (a JIT variant's arrays do not take NumPy
    # scalars), then give the caller its variant back.
    previous = mi.variant()
    mi.set_variant("scalar_rgb")
    try:
        nodes = np.linspace(360.0, 830.0, 95)
        cmf = np.array([list(mi.cie1931_xyz(float(w))) for w in nodes], np.float64)
        d65 = np.array([mi.cie_d65(float(w)) for w in nodes], np.float64)
        to_srgb = np.array([list(mi.xyz_to_srgb(mi.Color3f(*map(float, e)))) for e in np.eye(3)]).T
    finally:
        if previous is not None:
            mi.set_variant(previous)
    return nodes, cmf, d65, to_srgb


def srgb_weights(wavelengths, step: float = 0.005) -> np.ndarray:
    """Float64: per sample wavelength, the linear sRGB value under D65 of its piecewise-linear hat
    (zero outside the samples), ``to_srgb * int xyz(l) D65(l) hat(l) dl / int y``, integrated by
    the trapezoid rule on a ``step`` nm grid with the CIE tables interpolated linearly as Mitsuba
    does. ``P s = weights.T @ s`` projects a spectrum sampled at ``wavelengths``. (The Rust twin,
    ``nbrdf_core::spectrum::SrgbProjection``, integrates exactly.)"""
    wavelengths = np.asarray(wavelengths, np.float64)
    nodes, cmf, d65, to_srgb = _cie_tables()
    lo, hi = max(360.0, wavelengths[0]), min(830.0, wavelengths[-1])
    grid = np.linspace(lo, hi, int(round((hi - lo) / step)) + 1)
    weight = np.stack([np.interp(grid, nodes, cmf[:, c]) for c in range(3)], 1)
    weight *= np.interp(grid, nodes, d65)[:, None]
    out = np.empty((len(wavelengths), 3))
    for k in range(len(wavelengths)):
        hat = np.interp(grid, wavelengths, np.eye(len(wavelengths))[k])
        out[k] = to_srgb @ np.trapezoid(weight * hat[:, None], grid, axis=0) * CIE_Y_NORMALIZATION
    return out


# ---------------------------------------------------------------------------------------------
# Spectra


def test_file_spectra(shared: Path | None, count: int, rng) -> np.ndarray:
    """Spectra of the test files: RGB cell values of the shared RGL measurements (random RGB in
    [0, 1] where they are absent) times the basis of :mod:`nbrdf_tools.data.spectral_rgl`."""
    from nbrdf_tools.data import spectral_rgl

    rgb = []
    folder = shared / "data" / "rgl" if shared else None
    for path in sorted(folder.glob("*_rgb.bsdf")) if folder and folder.is_dir() else []:
        cells = spectral_rgl.read_tensor_file(path)["rgb"]
        cells = np.moveaxis(cells, 2, -1).reshape(-1, 3)
        cells = cells[cells.max(1) > 1e-3 * cells.max()]
        rgb.append(cells[rng.choice(len(cells), count // 4)])
    rgb = np.concatenate(rgb) if rgb else rng.uniform(0.0, 1.0, (count, 3))
    return rgb @ spectral_rgl.basis_spectra(GRID)


def smooth_spectra(count: int, rng) -> np.ndarray:
    """Reflectance-like spectra: a floor, one to three broad bumps (40-120 nm) and an optional
    sigmoid edge (10-40 nm), clipped at zero."""
    out = np.empty((count, len(GRID)))
    for i in range(count):
        s = np.full(len(GRID), rng.uniform(0.0, 0.3))
        for _ in range(rng.integers(1, 4)):
            centre, width = rng.uniform(380.0, 800.0), rng.uniform(40.0, 120.0)
            s += rng.uniform(-0.3, 0.8) * np.exp(-0.5 * ((GRID - centre) / width) ** 2)
        if rng.uniform() < 0.5:
            edge, width = rng.uniform(450.0, 700.0), rng.uniform(10.0, 40.0)
            s += rng.uniform(0.2, 0.8) / (1.0 + np.exp(-(GRID - edge) / width))
        out[i] = np.maximum(s, 0.0)
    return out


def conductor_spectra(material: str) -> np.ndarray:
    """``f cos`` of Mitsuba's ``roughconductor`` (alpha 0.1) with the measured ``material``
    index of refraction, per wavelength, at normal incidence and at 60 degrees (mirror pairs)."""
    import mitsuba as mi

    mi.set_variant("scalar_spectral")
    bsdf = mi.load_dict({"type": "roughconductor", "material": material, "alpha": 0.1})
    rows = []
    for theta in (0.0, np.radians(60.0)):
        view = [np.sin(theta), 0.0, np.cos(theta)]
        light = [-np.sin(theta), 0.0, np.cos(theta)]
        values = []
        for group in GRID.reshape(-1, 4) if len(GRID) % 4 == 0 else np.pad(
                GRID, (0, -len(GRID) % 4), mode="edge").reshape(-1, 4):
            si = mi.SurfaceInteraction3f()
            si.wi = mi.Vector3f(*view)
            si.wavelengths = mi.Spectrum(*group.tolist())
            values.extend(np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*light))).ravel())
        rows.append(np.array(values[:len(GRID)]))
    return np.array(rows)


# ---------------------------------------------------------------------------------------------
# Representations


def _hat_basis(count: int) -> np.ndarray:
    nodes = np.linspace(GRID[0], GRID[-1], count)
    return np.stack([np.interp(GRID, nodes, np.eye(count)[k]) for k in range(count)], 1)


def _bspline_basis(count: int) -> np.ndarray:
    from scipy.interpolate import BSpline

    degree = 3
    inner = np.linspace(GRID[0], GRID[-1], count - degree + 1)
    knots = np.concatenate([[GRID[0]] * degree, inner, [GRID[-1]] * degree])
    return BSpline.design_matrix(GRID, knots, degree).toarray()


def fit_linear(spectra: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Least-squares fits of every spectrum in the span of ``basis`` (grid x K)."""
    coefficients, *_ = np.linalg.lstsq(basis, spectra.T, rcond=None)
    return (basis @ coefficients).T


def fit_sigmoid_poly(spectra: np.ndarray, degree: int) -> np.ndarray:
    """Least-squares fits of ``scale * sigmoid(poly(x))`` (scale >= 0), from a few starts."""
    from scipy.optimize import least_squares

    x = (GRID - GRID.mean()) / (0.5 * (GRID[-1] - GRID[0]))
    powers = np.stack([x**j for j in range(degree + 1)], 1)

    def model(p):
        return p[-1] * 0.5 * (1.0 + np.tanh(0.5 * (powers @ p[:-1])))

    out = np.empty_like(spectra)
    for i, s in enumerate(spectra):
        peak = max(s.max(), 1e-12)
        best = None
        for start in ([0.0] * (degree + 1), [-1.0, 2.0] + [0.0] * (degree - 1),
                      [-1.0, -2.0] + [0.0] * (degree - 1)):
            p0 = np.array(start + [peak * 1.2])
            fit = least_squares(lambda p, s=s, peak=peak: (model(p) - s) / peak, p0, method="trf",
                                bounds=([-np.inf] * (degree + 1) + [0.0], np.inf), max_nfev=400)
            if best is None or fit.cost < best.cost:
                best = fit
        out[i] = model(best.x)
    return out


def errors(spectra: np.ndarray, fits: np.ndarray, weights: np.ndarray) -> dict:
    """Mean and worst relative RMS, relative max and sRGB errors over the spectra."""
    rms = np.sqrt(np.mean((fits - spectra) ** 2, 1)) / np.sqrt(np.mean(spectra**2, 1))
    peak = np.max(np.abs(fits - spectra), 1) / np.max(np.abs(spectra), 1)
    p_s, p_g = spectra @ weights, fits @ weights
    srgb = np.linalg.norm(p_g - p_s, axis=1) / np.linalg.norm(p_s, axis=1)
    return {name: (float(np.mean(v)), float(np.max(v))) for name, v in
            (("rms", rms), ("max", peak), ("srgb", srgb))}


def representations(quick: bool):
    """(name, outputs, fit function) of every candidate."""
    counts = (4, 8, 16) if quick else (4, 6, 8, 12, 16)
    for k in counts:
        basis = _hat_basis(k)
        yield f"nodes {k}", k, lambda s, b=basis: fit_linear(s, b)
    for k in counts:
        basis = _bspline_basis(k)
        yield f"B-spline {k}", k, lambda s, b=basis: fit_linear(s, b)
    for d in (2, 4):
        yield f"sigmoid-poly {d}", d + 2, lambda s, d=d: fit_sigmoid_poly(s, d)


def measure(shared: Path | None, quick: bool = False, seed: int = 1) -> list[dict]:
    rng = np.random.default_rng(seed)
    count = 40 if quick else 100
    sets = {
        "test files": test_file_spectra(shared, count, rng),
        "smooth reflectances": smooth_spectra(count, rng),
        "Au": conductor_spectra("Au"),
        "Cu": conductor_spectra("Cu"),
    }
    weights = srgb_weights(GRID, step=0.01)
    rows = []
    for name, outputs, fit in representations(quick):
        row = {"representation": name, "outputs": outputs, "weights": output_weights(outputs)}
        for set_name, spectra in sets.items():
            row[set_name] = errors(spectra, fit(spectra), weights)
        rows.append(row)
    return rows


PAGE = "spectral-basis"


def tables(rows: list[dict]) -> list[str]:
    sets = [k for k in rows[0] if k not in ("representation", "outputs", "weights")]
    lines = []
    for metric, label in (("rms", "relative RMS error"), ("max", "relative max error"),
                          ("srgb", "sRGB projection error")):
        lines += [f"**{label}** (mean / worst over the set)", "",
                  "| representation | outputs | network weights | " + " | ".join(sets) + " |",
                  "|---|---|---|" + "---|" * len(sets)]
        for r in rows:
            cells = " | ".join(f"{r[s][metric][0]:.2%} / {r[s][metric][1]:.2%}" for s in sets)
            lines.append(f"| {r['representation']} | {r['outputs']} | {r['weights']} | {cells} |")
        lines.append("")
    return lines


def page(data: dict, opening: str | None = None) -> str:
    """The whole page from its stored data, ``{"run": {...}, "rows": measure()}``; ``opening``: the
    command that writes it from that data (default: the results page's own)."""
    from nbrdf_tools.common import stored_page

    opening = opening or stored_page.opening_command(PAGE)
    run = data["run"]
    lines = ["# Spectral output representations: error and cost", "",
             "```sh", f"{opening}   # this page, from its stored data",
             f"{run['command']}   # to measure anew (minutes; rewrites the data and the page)", "```", "",
             "How well each candidate output layer of a spectral network can represent spectra, as least-squares "
             "fits over 360-830 nm on a 2 nm grid (the best a network with that output could do; no network is "
             "trained here), and what it costs in weights. The sets: "
             f"{run['spectra']} spectra of the test files (RGB cells of the four shared RGL measurements times the "
             "Gaussian basis of `nbrdf_tools.data.spectral_rgl`: peaks 35-45 nm wide, the hardest set), "
             f"{run['spectra']} smooth reflectance-like random spectra (broad bumps and sigmoid edges), and `f cos` "
             "of Mitsuba's `roughconductor` (alpha 0.1) with the measured index of refraction of gold and copper "
             "at normal incidence and at 60 degrees (2 spectra each). Errors per spectrum: relative RMS "
             "`rms(g - s) / rms(s)`, relative max `max |g - s| / max |s|`, and the error of the linear sRGB "
             "projection under D65 `|Pg - Ps| / |Ps|`; each cell is the mean / the worst over the set. "
             f"\"network weights\" is the 6-21-21-K network ({RGB_WEIGHTS} for RGB; the budget is 2x, "
             f"{2 * RGB_WEIGHTS}). Run of {run['date']} on {run['machine']}: {run['cpu_seconds']:.0f} s CPU, "
             f"{run['wall_seconds'] / 60:.0f} min wall, nearly all of it the sigmoid fits.", "",
             "The choice and its reason: [design.md section 9](../design.md#9-real-measured-data-rgl-materials), "
             "\"Spectral networks\".", "",
             "## Tables", "", *tables(data["rows"])]
    return "\n".join(lines).rstrip("\n") + "\n"


def main(argv=None) -> int:
    import os
    import time

    from nbrdf_tools.common import stored_page

    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools spectral-basis",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("--shared", type=Path, default=None,
                        help="the shared data folder (default: $NBRDF_SHARED or ../shared)")
    parser.add_argument("--out", "--output", type=Path,
                        help="write the page here (and its data to --data)")
    stored_page.add_arguments(parser, PAGE, out=False)
    parser.add_argument("--quick", action="store_true", help="fewer spectra and candidates")
    args = parser.parse_args(argv)
    if args.stored_only:
        out = args.out or stored_page.page_path(PAGE)
        stored_page.write(out, page(stored_page.load(stored_page.data_for(args, PAGE))))
        print(f"wrote {out} from {stored_page.data_for(args, PAGE)}")
        return 0
    shared = args.shared
    if shared is None:
        from nbrdf_tools.common.paths import shared_dir

        shared = shared_dir()
    wall, cpu = time.perf_counter(), time.process_time()
    rows = measure(shared, quick=args.quick)
    command = "python -m nbrdf_tools spectral-basis" + (" --quick" if args.quick else "") + \
        (f" --out {args.out}" if args.out else "")
    data = {"run": {"command": command, "date": time.strftime("%Y-%m-%d"), "spectra": 40 if args.quick else 100,
                    "machine": f"{os.cpu_count()} cores (load average {os.getloadavg()[0]:.1f} at the end)",
                    "cpu_seconds": time.process_time() - cpu, "wall_seconds": time.perf_counter() - wall},
            "rows": rows}
    if not args.out:
        print(page(data))
        return 0
    data_file = stored_page.save(stored_page.data_for(args, PAGE), data)
    text = page(data, stored_page.opening_command(PAGE, args.out, data_file))
    print(text)
    stored_page.write(args.out, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
