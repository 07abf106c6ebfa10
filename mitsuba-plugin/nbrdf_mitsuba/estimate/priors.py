"""What ties an estimate to the prior: the latent code's Gaussian penalty, the weight phase's
pull toward the decoded network (float64, its gradient backpropagated by hand), and the albedo
check that tells a material from a network that reflects more light than it receives."""

from __future__ import annotations

import functools

import drjit as dr
import mitsuba as mi
import numpy as np

from .models import _layers
from .numpy_network import backpropagate, hidden_and_output

#: Uniform direction pairs (above the horizon, a fixed draw) at which the pull compares the networks.
PULL_PAIRS = 4096
PULL_SEED = 7
#: A decoded candidate whose network reflects more than this share of the light it receives (its
#: directional albedo, at some incidence angle and channel) is not a material: it is never chosen,
#: nor kept as the final network. The held-out view cannot see it, because the excess lies where no
#: training light fell, and such a network renders the novel views far worse. Above 1 because an
#: estimate carries the images' noise, while the decoded training codes stay well below 1
#: (docs/experiments.md, Estimation: "The albedo check instead of the common candidate"). The
#: ceiling of :func:`albedo_bound`.
ALBEDO_BOUND = 1.5
#: Incidence angles (degrees, at most) where the lights fall square onto the object: there the
#: images constrain the albedo best, and an estimate's albedo above 1 is what they ask for, not
#: light where no image shows it (docs/experiments.md, Estimation: "The albedo bound from the lit
#: incidence angles").
ALBEDO_LIT_INCIDENCE = 45
#: Share above 1 (or above the network's own albedo up to ``ALBEDO_LIT_INCIDENCE``) that the bound
#: allows at any incidence angle: the quadrature's error and the images' noise.
ALBEDO_MARGIN = 0.1
#: Incidence angles (degrees) of the albedo check, and its half-vector grid: ``theta_h`` by
#: ``(pi / 2) u^2`` (dense at the specular peak), ``phi_h`` uniform.
ALBEDO_INCIDENCE = (0, 15, 30, 45, 60, 70, 80, 87)
ALBEDO_GRID = (96, 48)


def code_penalty(center: np.ndarray, variance: np.ndarray, strength: float):
    """``strength`` times the mean squared standardised distance to ``center``, and its gradient:
    the code's Gaussian penalty (the training codes' mean and variance)."""
    if strength == 0:
        return None

    def penalty(x):
        d = x - center
        return strength * float(np.mean(d * d / variance)), strength * 2.0 * d / variance / d.size

    return penalty


def _pull_inputs() -> np.ndarray:
    """The network input (``PULL_PAIRS``, 6) of the pull's direction pairs, each direction uniform
    over the hemisphere (the plugin's own warp and input: ``jit.uniform_hemisphere``,
    ``jit.network_input``)."""
    from .. import jit

    u = [mi.Float(row.astype(np.float32)) for row in np.random.default_rng(PULL_SEED).random((4, PULL_PAIRS))]
    x = jit.network_input(jit.uniform_hemisphere(u[0], u[1]), jit.uniform_hemisphere(u[2], u[3]))
    return np.stack([np.zeros(PULL_PAIRS) if c is None else np.asarray(dr.detach(c).numpy(), np.float64).reshape(-1)
                     for c in x], axis=1)


def pull_penalty(center: np.ndarray, strength: float):
    """The weight phase's pull toward the decoded network ``center`` (flat weights): ``strength``
    times the mean squared difference of the two networks' log-space outputs (the ``z`` of ``f =
    e^z - 1``, every channel) at ``PULL_PAIRS`` fixed uniform direction pairs, and its gradient
    (backpropagated by hand, float64 like the optimiser). A pull in function space, not in weight
    space: weights far apart can be the same BRDF and near ones different, while this keeps the
    BRDF itself where no image constrains it. ``None`` for strength 0."""
    if strength == 0:
        return None
    x = _pull_inputs()
    target = hidden_and_output(_layers(np.asarray(center, np.float64)), x)[2]

    def penalty(flat):
        layers = _layers(flat)
        z1, z2, z3 = hidden_and_output(layers, x)
        d = z3 - target
        return strength * float(np.mean(d * d)), backpropagate(layers, x, z1, z2, strength * 2.0 * d / d.size)

    return penalty


@functools.cache
def _albedo_quadrature() -> tuple[np.ndarray, np.ndarray]:
    """Network inputs ``(K N, 6)`` and weights ``(K, N)`` of the directional albedo ``a(l) = int
    f(v, l) cos theta_v dv`` at the ``K`` incidence angles of ``ALBEDO_INCIDENCE``: the integral
    over the half vector ``h`` (``v = 2 (h.l) h - l``, ``dv = 4 (h.l) dh``), midpoints of the
    ``ALBEDO_GRID``, so that a narrow specular peak is resolved where a grid over ``v`` would
    alias it. The inputs are the plugin's own (``jit.network_input``)."""
    from .. import jit

    n_theta, n_phi = ALBEDO_GRID
    u = (np.arange(n_theta) + 0.5) / n_theta
    theta = 0.5 * np.pi * u * u
    phi = 2 * np.pi * (np.arange(n_phi) + 0.5) / n_phi
    theta, phi = (a.ravel() for a in np.meshgrid(theta, phi, indexing="ij"))
    d_area = np.repeat(np.pi * u / n_theta, n_phi) * (2 * np.pi / n_phi) * np.sin(theta)  # d theta d phi sin theta
    h = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    angles = np.radians(ALBEDO_INCIDENCE)
    light = np.stack([np.sin(angles), np.zeros_like(angles), np.cos(angles)], axis=1)
    h_dot_l = light @ h.T  # (K, N)
    view = 2 * h_dot_l[..., None] * h[None] - light[:, None]
    weights = np.where((h_dot_l > 0) & (view[..., 2] > 0), view[..., 2] * 4 * h_dot_l * d_area, 0.0)

    def vector(a):
        return mi.Vector3f(*(mi.Float(a[:, i].astype(np.float32)) for i in range(3)))

    lights = np.repeat(light, h.shape[0], axis=0)
    x = jit.network_input(vector(view.reshape(-1, 3)), vector(lights))
    x = np.stack([np.zeros(len(lights)) if c is None else np.asarray(dr.detach(c).numpy(), np.float64).reshape(-1)
                  for c in x], axis=1)
    return x, weights


def directional_albedo(flat: np.ndarray) -> np.ndarray:
    """The directional albedo ``(K, 3)`` of flat width-21 weights at the incidence angles of
    ``ALBEDO_INCIDENCE`` (:func:`_albedo_quadrature`): at most 1 for a material that conserves
    energy."""
    x, weights = _albedo_quadrature()
    z = hidden_and_output(_layers(np.asarray(flat, np.float64)), x)[2]
    f = np.maximum(np.expm1(z), 0.0).reshape(*weights.shape, 3)
    return np.einsum("knc,kn->kc", f, weights)


def albedo_bound(albedo: np.ndarray) -> float:
    """The largest directional albedo a network of albedo ``albedo`` (``(K, 3)``, at the incidence
    angles of ``ALBEDO_INCIDENCE``) may have and be a material: 1 (energy conservation), or its
    own largest albedo up to ``ALBEDO_LIT_INCIDENCE`` where that is higher (what the images ask
    for), plus ``ALBEDO_MARGIN``; never above ``ALBEDO_BOUND``."""
    lit = albedo[np.asarray(ALBEDO_INCIDENCE) <= ALBEDO_LIT_INCIDENCE].max()
    return float(min(ALBEDO_BOUND, max(1.0, lit) * (1.0 + ALBEDO_MARGIN)))


def albedo_check(flat: np.ndarray) -> tuple[float, bool]:
    """A network's largest directional albedo over the incidence angles and channels, and
    whether it passes the albedo check (at most :func:`albedo_bound`)."""
    albedo = directional_albedo(flat)
    largest = float(albedo.max())
    return largest, largest <= albedo_bound(albedo)

