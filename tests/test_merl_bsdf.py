"""The ``merl`` plugin reads MERL-format tables like a NumPy implementation of docs/design.md
section 3 (read with NumPy from the same file)."""

from __future__ import annotations

import mitsuba as mi
import numpy as np

from nbrdf_testing import (SCALE, bsdf_eval, cell_centre_angles, f32, float32_rtol, from_angles, grazing_pairs, is_jit,
                           merl_trilinear, normalize, random_pairs, read_merl, to_angles, write_merl)


def load(path, **extra):
    return mi.load_dict({"type": "merl", "filename": str(path), **extra})


def above(light, view, margin=1e-3):
    return (normalize(light)[2] > margin) & (normalize(view)[2] > margin)


def test_cell_centres_reproduce_stored_values(variant, merl_table):
    stored = read_merl(merl_table)
    rng = np.random.default_rng(11)
    n = 600 if is_jit() else 80
    i_th, i_td, i_pd = rng.integers(0, 90, n), rng.integers(0, 90, n), rng.integers(0, 180, n)
    # Include the borders of every axis.
    i_th[:6], i_td[6:12], i_pd[12:18] = [0, 1, 2, 87, 88, 89], [0, 1, 2, 87, 88, 89], [0, 1, 2, 177, 178, 179]
    theta_h, theta_d, phi_d = cell_centre_angles(i_th, i_td, i_pd)
    light, view = from_angles(theta_h, rng.uniform(-np.pi, np.pi, n), theta_d, phi_d)  # phi_h arbitrary
    keep = above(light, view, 1e-2)
    light, view = f32(light[:, keep]), f32(view[:, keep])
    expected = stored[:, i_th[keep], i_td[keep], i_pd[keep]] * SCALE[:, None] * normalize(light)[2]
    got = bsdf_eval(load(merl_table), view, light)
    # float32 directions move the continuous index by ~1e-5 cells around the centre.
    np.testing.assert_allclose(got, expected, rtol=float32_rtol(2e-5), atol=1e-9)
    assert keep.sum() > n // 3


def test_trilinear_matches_numpy_reference(variant, merl_table):
    stored = read_merl(merl_table)
    bsdf = load(merl_table)
    n = 500 if is_jit() else 60
    rng = np.random.default_rng(5)
    # Points between cell centres near the borders: theta_h below the first centre (clamped),
    # phi_d near 0 and near pi (wrapped), theta_d close to 90 degrees.
    u = rng.uniform(0, 1, n)
    special_th = np.where(u < 0.5, rng.uniform(0, 0.8, n), rng.uniform(0, 90, n))
    special = from_angles((special_th / 90) ** 2 * np.pi / 2, rng.uniform(-np.pi, np.pi, n),
                          rng.uniform(0, 1, n) ** 0.3 * np.pi / 2,
                          np.where(rng.uniform(0, 1, n) < 0.5, rng.normal(0, 0.02, n), np.pi + rng.normal(0, 0.02, n)))
    for kind, (light, view) in (("random", random_pairs(n, 3)), ("grazing", grazing_pairs(n, 4)), ("border", special)):
        keep = above(light, view)
        light, view = f32(light[:, keep]), f32(view[:, keep])
        got = bsdf_eval(bsdf, view, light)
        ref = merl_trilinear(stored, light, view) * normalize(light)[2]
        np.testing.assert_allclose(got, ref, rtol=float32_rtol(1e-5), atol=1e-9, err_msg=kind)


def test_invalid_cells_are_skipped(variant, merl_table, tmp_path):
    stored = read_merl(merl_table).copy()
    # Knock out a block of cells (every channel), one channel of another cell, and a cell whose
    # whole neighbourhood is invalid.
    stored[:, 40:43, 30:33, 60:63] = -1.0
    stored[1, 50, 20, 100] = -1.0
    stored[:, 60:62, 10:12, 90:92] = -1.0
    path = write_merl(tmp_path / "holes.binary", stored)
    bsdf = load(path)
    rng = np.random.default_rng(9)
    n = 300 if is_jit() else 40
    # Points scattered around the holes (continuous index +-1.5 cells).
    centres = np.array([[41.5, 31.5, 61.5], [50.5, 20.5, 100.5], [61.0, 11.0, 91.0]])
    idx = centres[rng.integers(0, 3, n)] + rng.uniform(-1.5, 1.5, (n, 3))
    theta_h = (idx[:, 0] / 90) ** 2 * np.pi / 2
    light, view = from_angles(theta_h, rng.uniform(-np.pi, np.pi, n), idx[:, 1] / 90 * np.pi / 2, idx[:, 2] / 180 * np.pi)
    keep = above(light, view)
    light, view = f32(light[:, keep]), f32(view[:, keep])
    got = bsdf_eval(bsdf, view, light)
    ref = merl_trilinear(stored, light, view) * normalize(light)[2]
    np.testing.assert_allclose(got, ref, rtol=float32_rtol(1e-5), atol=1e-9)
    # The centre of the fully invalid 2x2x2 block sees no valid neighbour: 0.
    light, view = from_angles([(61.0 / 90) ** 2 * np.pi / 2], [0.3], [11.0 / 90 * np.pi / 2], [91.0 / 180 * np.pi])
    assert np.all(bsdf_eval(bsdf, f32(view), f32(light)) == 0)


def test_reciprocity(variant, merl_table):
    bsdf = load(merl_table)
    view, light = (f32(a) for a in random_pairs(300 if is_jit() else 40, 21))
    forward = bsdf_eval(bsdf, view, light) / normalize(light)[2]
    backward = bsdf_eval(bsdf, light, view) / normalize(view)[2]
    np.testing.assert_allclose(forward, backward, rtol=1e-5, atol=1e-9)


def test_reference_helpers_round_trip():
    """The test's own Rusinkiewicz helpers invert each other (guards the reference)."""
    rng = np.random.default_rng(0)
    n = 100
    angles = (rng.uniform(0, 1.5, n), rng.uniform(-3, 3, n), rng.uniform(0, 1.5, n), rng.uniform(-3, 3, n))
    light, view = from_angles(*angles)
    theta_h, phi_h, theta_d, phi_d, _ = to_angles(light, view)
    for a, b in zip(angles, (theta_h, phi_h, theta_d, phi_d)):
        np.testing.assert_allclose(a, b, atol=1e-9)
