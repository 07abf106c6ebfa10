"""``nbrdf_tools.pages.spectral_basis`` (the measurement behind the choice of a spectral network's
output, docs/results/spectral-basis.md): each candidate reproduces exactly what it can represent
(closed forms), the sRGB projection of a unit spectrum is white, and the weight count is the RGB
network's for three outputs."""

from __future__ import annotations

import numpy as np

from nbrdf_tools.pages import spectral_basis as sb


def test_weights_count_the_network():
    assert sb.output_weights(3) == 675          # the RGB network, 6-21-21-3
    assert sb.output_weights(16) - sb.output_weights(15) == 22


def test_each_representation_reproduces_its_own_family():
    nodes = np.linspace(sb.GRID[0], sb.GRID[-1], 8)
    polyline = np.interp(sb.GRID, nodes, np.linspace(0.2, 1.4, 8) ** 2)[None]
    np.testing.assert_allclose(sb.fit_linear(polyline, sb._hat_basis(8)), polyline, atol=1e-12)
    x = (sb.GRID - 600.0) / 235.0
    cubic = (0.5 + 0.3 * x - 0.2 * x**2 + 0.4 * x**3)[None]
    np.testing.assert_allclose(sb.fit_linear(cubic, sb._bspline_basis(6)), cubic, atol=1e-10)
    u = (sb.GRID - sb.GRID.mean()) / (0.5 * (sb.GRID[-1] - sb.GRID[0]))
    sigmoid = (2.5 / (1.0 + np.exp(-(-0.5 + 3.0 * u - 1.5 * u**2))))[None]
    np.testing.assert_allclose(sb.fit_sigmoid_poly(sigmoid, 2), sigmoid, rtol=1e-5)
    errors = sb.errors(sigmoid, sb.fit_linear(sigmoid, sb._hat_basis(4)), sb.srgb_weights(sb.GRID, 0.05))
    assert errors["rms"][0] > 1e-3                      # not everything fits everything


def test_a_unit_spectrum_projects_to_white():
    weights = sb.srgb_weights([360.0, 600.0, 830.0])
    np.testing.assert_allclose(weights.sum(0), [1.0, 1.0, 1.0], atol=3e-4)
