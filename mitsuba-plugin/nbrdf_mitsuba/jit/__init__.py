"""The rendering formulas of the Rust library written as Dr.Jit arithmetic, one module per
concern:

* :mod:`.fastmath`: ReLU, the exp clamp and ``exp(x) - 1`` (``fastmath.rs``);
* :mod:`.directions`: unit directions, zero and non-finite vectors included;
* :mod:`.network`: the network input and forward pass (:class:`TracedNetwork`);
* :mod:`.sampling`: each sampling strategy's sampler beside its pdf, the tabulated sampler
  (:class:`TracedTable`) and :func:`sample` / :func:`pdf` by strategy name;
* :mod:`.merl`: the MERL table lookup (:class:`TracedMerl`);
* :mod:`.textured`: spatially varying materials: the latent texture's lookup
  (:class:`TracedUvMapping`), the lobe channels' strategy (:func:`lobe_parameters`) and the
  material (:class:`TracedTexturedMaterial`);
* :mod:`.spectral`: the output stage of spectral variants: Mitsuba's RGB-to-spectrum lookup per
  lane (:class:`SrgbModel`, :func:`spectrum_from_rgb`) and spectral networks' B-spline basis.

Why a second copy: traced into Mitsuba's own kernels, a scene with NBRDFs keeps Dr.Jit's symbolic
(megakernel) mode and runs on CUDA as well as LLVM. The Rust code stays the reference; each
function here is a deliberate twin of one there. Which twin, and the test holding the two
together: docs/design.md, "Twins" (the twin table, checked by tests/test_twin_map.py).

The package re-exports each module's public names. Settings read at trace time live in their
module: patch ``jit.network.AUTO_LITERAL_MAX``, not the copy here.
"""

from __future__ import annotations

from .directions import both_valid_above, cos_theta, unit, unit_or_normal, unit_vector
from .fastmath import EXP_ARG_MAX, EXP_ARG_MIN, clamp_exp_argument, expm1, relu
from .merl import TracedMerl
from .network import AUTO_LITERAL_MAX, SIN_THETA_H_EPS_F32, WEIGHT_MODES, TracedNetwork, live_networks, network_input
from .sampling import (
    MAX_EXPONENT,
    STRATEGIES,
    TracedTable,
    anisotropic_half_vector,
    anisotropic_pdf,
    cosine_hemisphere,
    mixture_pdf,
    pdf,
    phong_half_vector,
    sample,
    two_lobe_pdf,
    uniform_hemisphere,
    unit_interval,
)
from .spectral import SrgbModel, bspline_weights, spectral_value, spectrum_from_rgb, srgb_model, srgb_projection
from .textured import TracedTexturedMaterial, TracedUvMapping, lobe_parameters

__all__ = [
    "AUTO_LITERAL_MAX", "EXP_ARG_MAX", "EXP_ARG_MIN", "MAX_EXPONENT", "SIN_THETA_H_EPS_F32", "STRATEGIES",
    "WEIGHT_MODES", "SrgbModel", "TracedMerl", "TracedNetwork", "TracedTable", "TracedTexturedMaterial",
    "TracedUvMapping", "anisotropic_half_vector", "anisotropic_pdf", "both_valid_above", "bspline_weights",
    "clamp_exp_argument", "cos_theta", "cosine_hemisphere", "expm1", "live_networks", "lobe_parameters",
    "mixture_pdf", "network_input", "pdf", "phong_half_vector", "relu", "sample", "spectral_value",
    "spectrum_from_rgb", "srgb_model", "srgb_projection", "two_lobe_pdf", "uniform_hemisphere", "unit",
    "unit_interval", "unit_or_normal", "unit_vector",
]
