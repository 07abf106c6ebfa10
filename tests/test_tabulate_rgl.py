"""`python -m nbrdf_mitsuba.tabulate_rgl`: a real RGL measurement tabulated onto the MERL grid
holds, at cell centres, what Mitsuba's `measured` plugin evaluates there (the independent
reference), marks cells below the horizon as not measured, and is a valid MERL file."""

from __future__ import annotations

import subprocess
import sys

import mitsuba as mi
import numpy as np

from nbrdf_testing import SCALE, cell_centre_angles, from_angles, read_merl


def test_tabulated_rgl_matches_measured(llvm_variant, shared, tmp_path):
    source = shared / "data" / "rgl" / "paper_white_rgb.bsdf"
    table = tmp_path / "paper_white.binary"
    done = subprocess.run([sys.executable, "-m", "nbrdf_mitsuba.tabulate_rgl", str(source), "-o", str(table)],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert table.stat().st_size == 34_992_012
    stored = read_merl(table)

    rng = np.random.default_rng(2)
    n = 400
    i_th, i_td, i_pd = rng.integers(0, 90, n), rng.integers(0, 90, n), rng.integers(0, 180, n)
    theta_h, theta_d, phi_d = cell_centre_angles(i_th, i_td, i_pd)
    light, view = from_angles(theta_h, np.zeros(n), theta_d, phi_d)
    above = (light[2] > 1e-3) & (view[2] > 1e-3)
    below = (light[2] <= 0) | (view[2] <= 0)
    assert np.all(stored[:, i_th[below], i_td[below], i_pd[below]] == -1.0)

    bsdf = mi.load_dict({"type": "measured", "filename": str(source)})

    def e(wi, wo):  # Mitsuba's eval: f_r cos(wo), negatives (out of gamut) clamped as the tool does
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(wi[:, above].astype(np.float32))
        value = np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(wo[:, above].astype(np.float32))))
        return np.maximum(value.reshape(3, -1), 0.0)

    # The measurement is not reciprocal: the default (reciprocal) table holds the cosine-weighted
    # mean of the estimates for both orderings of light and view.
    cl, cv = light[2, above], view[2, above]
    expected = (e(view, light) + e(light, view)) / (cl + cv)
    got = stored[:, i_th[above], i_td[above], i_pd[above]] * SCALE[:, None]
    np.testing.assert_allclose(got, expected, rtol=1e-4, atol=1e-7)
    assert expected.mean() > 0.1  # paper white: albedo ~0.9, f_r ~0.28


def test_missing_input_is_a_clear_error(tmp_path):
    missing = tmp_path / "nothing.bsdf"
    done = subprocess.run([sys.executable, "-m", "nbrdf_mitsuba.tabulate_rgl", str(missing)],
                          capture_output=True, text=True)
    assert done.returncode == 2 and "nothing.bsdf" in done.stderr
