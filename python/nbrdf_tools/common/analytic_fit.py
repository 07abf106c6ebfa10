"""Analytic BRDF models fitted to measured data, the way a Mitsuba user would replace a
measurement by a model: GGX ``roughconductor`` and ``roughplastic`` (Mitsuba's own plugins),
the 7-parameter Blinn-Phong model, and the ABC (Löw et al. 2012) and SGD (Bagher et al. 2012)
forms whose published MERL fits nbrdf embeds.

Every model is an ``eval_cos(x, view, light)`` of a parameter vector ``x`` and local (3, n)
directions, giving ``f_r(view, light) cos(theta_light)`` (3, n), Mitsuba's ``eval`` convention
(``si.wi = view``, ``wo = light``). A fit minimises the log-space residual
``ln(1 + f cos) - ln(1 + f_ref cos)`` over channels and a fixed set of directions (half
adaptive: uniform in theta_h, theta_d, phi_d; half uniform over the hemisphere) with
``scipy.optimize.least_squares`` (trust-region reflective, bounds), from several starts.

The NumPy forms are deliberate second copies (docs/design.md's twin table lists those of Rust
forms); each names its twin and the test holding them together (tests/test_fidelity_report.py):

* :func:`ggx_conductor_eval_cos`: Mitsuba's ``roughconductor`` (``distribution ggx``,
  ``material none``: Fresnel 1), ``test_numpy_ggx_matches_mitsuba_roughconductor``;
* :func:`ggx_aniso_conductor_eval_cos`: the same with ``alpha_u``, ``alpha_v`` (Mitsuba's
  ``MicrofacetDistribution`` ``eval`` and ``smith_g1``),
  ``test_numpy_anisotropic_ggx_matches_mitsuba_roughconductor``;
* :func:`blinn_phong_eval_cos`: ``nbrdf-core/src/fit/phong.rs`` ``PhongParams::eval``
  (``f = kd / pi + ks (n + 2) / (2 pi) cos(theta_h)^n``), closed form checked in
  ``test_fit_recovers_blinn_phong``;
* :func:`abc_eval_cos`: ``nbrdf-core/src/analytic/abc.rs``, ``test_numpy_abc_sgd_match_rust_tables``
  (against ``nbrdf synth --model abc`` tables at cell centres);
* :func:`sgd_eval_cos`: ``nbrdf-core/src/analytic/sgd.rs``, the same test with ``--model sgd``.

``roughplastic`` has no NumPy copy: its diffuse term uses Mitsuba's precomputed rough-interface
transmittance, so the fit evaluates Mitsuba's plugin itself, once per roughness, as the two
basis functions of its linear parameters (``diffuse_reflectance`` and ``specular_reflectance``
enter ``eval`` linearly with ``nonlinear = false``; the test checks that too).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nbrdf_tools.common.paths import REPO

# The published SGD and ABC fits of the 100 MERL materials, embedded in the Rust library.
FITS_JSON = REPO / "nbrdf-core" / "data" / "merl_fits.json"
# nbrdf-core/src/analytic/mod.rs MIN_COS: floor of the cosines of 1 / (l.z v.z).
MIN_COS = 1e-6
# Random stream of the fitting directions (compare_materials' metric directions use stream 6).
FIT_STREAM = 11
# The azimuths of turned fitting directions (compare_materials' turned metric directions use 13).
FIT_TURN_STREAM = 14
# Relative index of roughplastic's dielectric coating (Mitsuba's default polypropylene, 1.49,
# rounded to the 1.5 of most fits).
PLASTIC_IOR = 1.5


# --------------------------------------------------------------------------------------------
# Geometry


@dataclass
class Geometry:
    """Unit light, view and half vectors (3, n) and which pairs lie above the horizon."""

    l: np.ndarray
    v: np.ndarray
    h: np.ndarray
    c: np.ndarray  # l . h, clamped to [0, 1]
    above: np.ndarray

    @classmethod
    def of(cls, view: np.ndarray, light: np.ndarray) -> Geometry:
        v = np.asarray(view, np.float64)
        l = np.asarray(light, np.float64)
        v = v / np.linalg.norm(v, axis=0)
        l = l / np.linalg.norm(l, axis=0)
        h = l + v
        h = h / np.maximum(np.linalg.norm(h, axis=0), 1e-300)
        above = (l[2] > 0) & (v[2] > 0)
        return cls(l=l, v=v, h=h, c=np.clip(np.sum(l * h, axis=0), 0.0, 1.0), above=above)


def _finite_non_negative(x: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(x) & (x > 0), x, 0.0)


# --------------------------------------------------------------------------------------------
# The models (f_r cos(theta_light), (3, n))


def ggx_d(cos_h: np.ndarray, alpha: float) -> np.ndarray:
    """Mitsuba's isotropic GGX normal distribution ``D(m)``."""
    cos2 = cos_h * cos_h
    a2 = alpha * alpha
    # 1 / (pi a^2 cos^4 (1 + tan^2 / a^2)^2), written without the tangent.
    denom = math.pi * a2 * (cos2 + (1.0 - cos2) / a2) ** 2
    return np.where(cos_h > 0, 1.0 / denom, 0.0)


def ggx_g1(cos_v: np.ndarray, alpha: float) -> np.ndarray:
    """Mitsuba's GGX Smith masking ``G1`` of a direction above the horizon."""
    tan2 = np.maximum(1.0 - cos_v * cos_v, 0.0) / np.maximum(cos_v * cos_v, 1e-300)
    return 2.0 / (1.0 + np.sqrt(1.0 + alpha * alpha * tan2))


def ggx_conductor_eval_cos(x, view, light) -> np.ndarray:
    """``roughconductor`` (GGX, ``material none``): ``x = (R_r, R_g, R_b, alpha)``;
    ``f = R D(h) G1(v) G1(l) / (4 v.z l.z)``."""
    g = Geometry.of(view, light)
    r, alpha = np.asarray(x[:3])[:, None], float(x[3])
    # G1 is zero where a direction faces away from h; with both above the horizon and h their
    # bisector, it never does.
    lobe = ggx_d(g.h[2], alpha) * ggx_g1(g.v[2], alpha) * ggx_g1(g.l[2], alpha) / (4.0 * g.v[2])
    return np.where(g.above, _finite_non_negative(r * lobe), 0.0)


def ggx_aniso_d(h: np.ndarray, alpha_u: float, alpha_v: float) -> np.ndarray:
    """Mitsuba's anisotropic GGX ``D(m) = 1 / (pi a_u a_v ((m_x/a_u)^2 + (m_y/a_v)^2 + m_z^2)^2)``."""
    q = (h[0] / alpha_u) ** 2 + (h[1] / alpha_v) ** 2 + h[2] ** 2
    return np.where(h[2] > 0, 1.0 / (math.pi * alpha_u * alpha_v * q * q), 0.0)


def ggx_aniso_g1(d: np.ndarray, alpha_u: float, alpha_v: float) -> np.ndarray:
    """Mitsuba's anisotropic GGX Smith ``G1`` of a direction above the horizon (the projected
    roughness ``(a_u d_x)^2 + (a_v d_y)^2`` over ``d_z^2`` in place of ``alpha^2 tan^2``)."""
    xy = (alpha_u * d[0]) ** 2 + (alpha_v * d[1]) ** 2
    return 2.0 / (1.0 + np.sqrt(1.0 + xy / np.maximum(d[2] * d[2], 1e-300)))


def ggx_aniso_conductor_eval_cos(x, view, light) -> np.ndarray:
    """Anisotropic ``roughconductor`` (GGX, ``material none``): ``x = (R_r, R_g, R_b, alpha_u,
    alpha_v)``, ``alpha_u`` along the tangent (local x); ``f = R D(h) G1(v) G1(l) / (4 v.z l.z)``."""
    g = Geometry.of(view, light)
    r, au, av = np.asarray(x[:3])[:, None], float(x[3]), float(x[4])
    lobe = ggx_aniso_d(g.h, au, av) * ggx_aniso_g1(g.v, au, av) * ggx_aniso_g1(g.l, au, av) / (4.0 * g.v[2])
    return np.where(g.above, _finite_non_negative(r * lobe), 0.0)


def blinn_phong_eval_cos(x, view, light) -> np.ndarray:
    """``x = (kd_rgb, ks_rgb, n)``: ``f = kd / pi + ks (n + 2) / (2 pi) cos(theta_h)^n``."""
    g = Geometry.of(view, light)
    kd, ks, n = np.asarray(x[:3])[:, None], np.asarray(x[3:6])[:, None], float(x[6])
    lobe = (n + 2.0) / (2.0 * math.pi) * np.exp(n * np.log(np.maximum(g.h[2], 1e-12)))
    f = kd / math.pi + ks * lobe
    return np.where(g.above, f * g.l[2], 0.0)


def fresnel_unpolarised(ior: float, c: np.ndarray) -> np.ndarray:
    """abc.rs ``fresnel_unpolarised``: unpolarised dielectric Fresnel reflectance at ``cos = c``."""
    g2 = ior * ior + c * c - 1.0
    g = np.sqrt(np.maximum(g2, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = (g - c) / (g + c)
        tail = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        f = 0.5 * ratio * ratio * (1.0 + tail * tail)
    return np.where((g2 < 0) | np.isnan(f), 1.0, f)


def abc_eval_cos(x, view, light) -> np.ndarray:
    """``x = (kd_rgb, A_rgb, B, C, ior)``:
    ``f = kd / pi + A / (1 + B (1 - h.z))^C F(l.h) G / (pi l.z v.z)`` (Cook-Torrance's V-groove G)."""
    g = Geometry.of(view, light)
    kd, a = np.asarray(x[:3])[:, None], np.asarray(x[3:6])[:, None]
    b, c, ior = float(x[6]), float(x[7]), float(x[8])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        two_hz_over_c = 2.0 * g.h[2] / g.c
        masking = np.minimum(1.0, np.minimum(two_hz_over_c * g.l[2], two_hz_over_c * g.v[2]))
        masking = np.where(np.isnan(masking), 1.0, masking)
        lobe = (1.0 + b * (1.0 - g.h[2])) ** c
        specular = fresnel_unpolarised(ior, g.c) * masking / (
            math.pi * np.maximum(g.l[2], MIN_COS) * np.maximum(g.v[2], MIN_COS))
        f = _finite_non_negative(kd / math.pi + a / lobe * specular)
    return np.where(g.above, f * g.l[2], 0.0)


SGD_PARAMETERS = ("rho_d", "rho_s", "alpha", "p", "f0", "f1", "kap", "lambda", "c", "k", "theta0")


def sgd_channel(x, g: Geometry) -> np.ndarray:
    """One channel of SGD (sgd.rs ``SgdParams::channel``), ``x`` in :data:`SGD_PARAMETERS` order."""
    rho_d, rho_s, alpha, p, f0, f1, kap, lam, c, k, theta0 = (float(v) for v in x)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore", under="ignore"):
        fresnel = f0 - g.c * f1 + (1.0 - g.c) ** 5 * (1.0 - f0)
        cos2 = g.h[2] ** 2
        tan2 = np.maximum(1.0 - cos2, 0.0) / cos2
        a = alpha + tan2 / alpha
        decay = np.exp(-a)
        d = np.where((cos2 > 0) & (decay > 0), kap * decay / (math.pi * a**p * cos2 * cos2), 0.0)

        def shadow(cos_k):
            if lam == 0.0:
                return np.ones_like(cos_k)
            t = np.maximum(np.arccos(np.clip(cos_k, -1.0, 1.0)) - theta0, 0.0)
            s = 1.0 - lam * np.expm1(c * t**k)
            return np.where(np.isnan(s), 0.0, np.clip(s, 0.0, 1.0))

        specular = rho_s * fresnel * d * shadow(g.l[2]) * shadow(g.v[2]) / (
            np.maximum(g.l[2], MIN_COS) * np.maximum(g.v[2], MIN_COS))
        return _finite_non_negative((rho_d + specular) / math.pi)


def sgd_eval_cos(x, view, light) -> np.ndarray:
    """``x``: the 11 :data:`SGD_PARAMETERS` of red, then green, then blue (33 values)."""
    g = Geometry.of(view, light)
    x = np.asarray(x, np.float64).reshape(3, len(SGD_PARAMETERS))
    f = np.stack([sgd_channel(x[ch], g) for ch in range(3)])
    return np.where(g.above, f * g.l[2], 0.0)


def published_fits(path: Path = FITS_JSON) -> tuple[list[tuple[str, np.ndarray]], list[tuple[str, np.ndarray]]]:
    """The published MERL fits as parameter vectors: ``(abc, sgd)`` lists of (name, x)."""
    data = json.loads(Path(path).read_text(encoding="utf-8"))
    abc = [(m["name"], np.array([*m["kd"], *m["A"], m["B"], m["C"], m["ior"]], np.float64))
           for m in data["abc"]["materials"]]
    sgd = [(m["name"], np.array([[m[k][ch] for k in SGD_PARAMETERS] for ch in range(3)], np.float64).ravel())
           for m in data["sgd"]["materials"]]
    return abc, sgd


# --------------------------------------------------------------------------------------------
# Fitting


@dataclass
class FitData:
    """Directions and the reference's ``f cos(theta_light)`` (3, n) at them."""

    view: np.ndarray
    light: np.ndarray
    target: np.ndarray

    @property
    def log_target(self) -> np.ndarray:
        return np.log1p(np.maximum(self.target, 0.0))


def fit_directions(count: int, seed: int = 0, turned: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(view, light) (3, count): half adaptive, half uniform, both above the horizon, from
    compare_materials' SplitMix64 stream on a stream of their own. ``turned`` turns each pair
    about the normal by its own uniform angle (adaptive pairs have ``phi_h = 0``: an anisotropic
    fit needs the others)."""
    from nbrdf_tools.common.compare_materials import sample_directions, splitmix_uniforms, turn_about_normal

    views, lights = [], []
    for k, sampling in enumerate(("adaptive", "uniform")):
        want = count // 2 + (count % 2 if k == 0 else 0)
        u = splitmix_uniforms(seed, FIT_STREAM + k, 0, 3 * want + 64)
        light, view = sample_directions(sampling, u)
        keep = (light[2] > 1e-4) & (view[2] > 1e-4)
        if keep.sum() < want:
            raise RuntimeError("too few fitting directions above the horizon")
        views.append(view[:, keep][:, :want])
        lights.append(light[:, keep][:, :want])
    view, light = np.concatenate(views, axis=1), np.concatenate(lights, axis=1)
    if turned:
        angle = 2 * math.pi * splitmix_uniforms(seed, FIT_TURN_STREAM, 0, count)[:, 0]
        view, light = turn_about_normal(view, angle), turn_about_normal(light, angle)
    return view, light


@dataclass
class Model:
    """A fittable model: ``eval_cos(x, view, light)``, parameter names, bounds and starts."""

    name: str
    label: str
    parameters: list[str]
    lower: np.ndarray
    upper: np.ndarray
    eval_cos: Callable
    starts: Callable  # (FitData) -> list of x0
    max_nfev: int = 400
    # The indices of x that are fitted (the others keep their start's values); all when None.
    free: np.ndarray | None = None
    # Parameters optimised as their logarithm (scale-free, for exponents and roughnesses).
    log: tuple[str, ...] = ()
    # Models whose channels share no parameter: ``channel_eval_cos(x_channel, Geometry) -> (n,)``
    # fits each channel's ``len(parameters) // 3`` values on its own (x is channel-major).
    channel_eval_cos: Callable | None = None
    notes: str = ""


@dataclass
class Fit:
    model: str
    x: np.ndarray
    parameters: dict
    loss: float  # mean squared log residual
    seconds: float
    evaluations: int
    starts: int

    def to_json(self) -> dict:
        return {"model": self.model, "parameters": self.parameters, "loss": self.loss,
                "seconds": self.seconds, "evaluations": self.evaluations, "starts": self.starts}


def fit_loss(model: Model, x, data: FitData) -> float:
    """Mean squared log residual of ``x`` over the data's directions and channels."""
    r = np.log1p(model.eval_cos(x, data.view, data.light)) - data.log_target
    return float(np.mean(r * r))


def _least_squares(residual, x0: np.ndarray, lower, upper, log: np.ndarray, max_nfev: int) -> np.ndarray:
    """``x`` minimising ``|residual(x)|^2`` within bounds from ``x0``, the ``log`` entries
    optimised as logarithms."""
    from scipy.optimize import least_squares

    def to_z(x):
        return np.where(log, np.log(np.maximum(x, 1e-300)), x)

    def to_x(z):
        return np.where(log, np.exp(z), z)

    lo, hi = to_z(lower), to_z(upper)
    # Strictly inside the bounds (trf needs it).
    z0 = np.clip(to_z(x0), lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
    result = least_squares(lambda z: residual(to_x(z)), z0, bounds=(lo, hi), method="trf", x_scale="jac",
                           max_nfev=max_nfev, jac="2-point")
    return np.clip(to_x(result.x), lower, upper)


def fit_model(model: Model, data: FitData, starts_kept: int = 3) -> Fit:
    """Least-squares fit of ``model`` in log space; the best of its starts (of many starts, the
    ``starts_kept`` best are refined)."""
    start_time = time.perf_counter()
    y = data.log_target
    evaluations = 0
    n = len(model.parameters)
    free = np.arange(n) if model.free is None else np.asarray(model.free)
    log = np.array([p in model.log for p in model.parameters])

    starts = [np.clip(np.asarray(s, np.float64), model.lower, model.upper) for s in model.starts(data)]
    evaluations += len(starts) if len(starts) > starts_kept else 0
    if len(starts) > starts_kept:
        starts = sorted(starts, key=lambda s: fit_loss(model, s, data))[:starts_kept]
    if model.channel_eval_cos is not None:
        g = Geometry.of(data.view, data.light)
        k = n // 3
    best = None
    for x0 in starts:
        x = x0.copy()
        if model.channel_eval_cos is None:
            groups = [(free, None)]
        else:
            groups = [(free[(free >= ch * k) & (free < (ch + 1) * k)], ch) for ch in range(3)]
        for idx, ch in groups:
            def residual(z, idx=idx, ch=ch, x=x):
                nonlocal evaluations
                evaluations += 1
                trial = x.copy()
                trial[idx] = z
                if ch is None:
                    return (np.log1p(model.eval_cos(trial, data.view, data.light)) - y).ravel()
                value = np.where(g.above, model.channel_eval_cos(trial[ch * k:(ch + 1) * k], g) * g.l[2], 0.0)
                return np.log1p(value) - y[ch]

            x[idx] = _least_squares(residual, x[idx], model.lower[idx], model.upper[idx], log[idx], model.max_nfev)
        loss = fit_loss(model, x, data)
        if best is None or loss < best[0]:
            best = (loss, x)
    loss, x = best
    return Fit(model=model.name, x=x, parameters=dict(zip(model.parameters, (float(v) for v in x))),
               loss=loss, seconds=time.perf_counter() - start_time, evaluations=evaluations, starts=len(starts))


# --------------------------------------------------------------------------------------------
# The models a Mitsuba user has


def _reflectance_scale(data: FitData) -> float:
    """A rough diffuse albedo of the data: the median of f (its cosine removed) times pi."""
    f = data.target / np.maximum(data.light[2], 1e-3)
    return float(np.clip(np.median(f) * math.pi, 1e-3, 1.0))


def ggx_conductor_model() -> Model:
    def starts(data):
        return [[0.5, 0.5, 0.5, a] for a in (0.02, 0.08, 0.3, 0.8)]

    return Model(name="roughconductor", label="GGX `roughconductor`",
                 parameters=["specular_reflectance_r", "specular_reflectance_g", "specular_reflectance_b", "alpha"],
                 lower=np.array([0.0, 0.0, 0.0, 1e-3]), upper=np.array([1.0, 1.0, 1.0, 1.0]),
                 eval_cos=ggx_conductor_eval_cos, starts=starts, log=("alpha",),
                 notes="specular_reflectance in [0, 1], material none (Fresnel 1)")


def ggx_aniso_conductor_model() -> Model:
    def starts(data):
        return [[0.5, 0.5, 0.5, au, av] for au in (0.03, 0.15, 0.5) for av in (0.03, 0.15, 0.5)]

    return Model(name="roughconductor_aniso", label="anisotropic GGX `roughconductor`",
                 parameters=["specular_reflectance_r", "specular_reflectance_g", "specular_reflectance_b",
                             "alpha_u", "alpha_v"],
                 lower=np.array([0.0, 0.0, 0.0, 1e-3, 1e-3]), upper=np.array([1.0, 1.0, 1.0, 1.0, 1.0]),
                 eval_cos=ggx_aniso_conductor_eval_cos, starts=starts, log=("alpha_u", "alpha_v"),
                 notes="specular_reflectance in [0, 1], alpha_u along the tangent, alpha_v across it, "
                       "material none (Fresnel 1)")


def blinn_phong_model() -> Model:
    def starts(data):
        kd = _reflectance_scale(data)
        return [[kd, kd, kd, 0.1, 0.1, 0.1, n] for n in (5.0, 50.0, 500.0, 5000.0)]

    return Model(name="blinn_phong", label="Blinn-Phong (7 parameters)",
                 parameters=["kd_r", "kd_g", "kd_b", "ks_r", "ks_g", "ks_b", "exponent"],
                 lower=np.array([0.0] * 6 + [0.01]), upper=np.array([1.0] * 3 + [10.0] * 3 + [1e6]),
                 eval_cos=blinn_phong_eval_cos, starts=starts, log=("exponent",))


def abc_model() -> Model:
    abc, _ = published_fits()

    def starts(data):
        return [x for _, x in abc]

    return Model(name="abc", label="ABC (Löw et al. 2012)",
                 parameters=["kd_r", "kd_g", "kd_b", "A_r", "A_g", "A_b", "B", "C", "ior"],
                 lower=np.array([0.0] * 3 + [1e-6] * 3 + [1.0, 0.01, 1.01]),
                 upper=np.array([1.0] * 3 + [1e5] * 3 + [1e8, 5.0, 100.0]),
                 eval_cos=abc_eval_cos, starts=starts, log=("A_r", "A_g", "A_b", "B"),
                 notes="started from the best three of the 100 published MERL fits")


def sgd_model() -> Model:
    _, sgd = published_fits()
    k = len(SGD_PARAMETERS)
    # Free per channel: rho_d, rho_s, alpha, p, f0, f1, lambda, theta0. kap is redundant with
    # rho_s, and c, k (c x^k with c down to 1e-8 and k up to 800) are too stiff for a
    # finite-difference Jacobian: they keep the start's values.
    free_names = ("rho_d", "rho_s", "alpha", "p", "f0", "f1", "lambda", "theta0")
    free = np.array([ch * k + SGD_PARAMETERS.index(n) for ch in range(3) for n in free_names])
    lo = {"rho_d": 0.0, "rho_s": 0.0, "alpha": 1e-6, "p": 0.0, "f0": -10.0, "f1": -10.0, "kap": 0.0,
          "lambda": 0.0, "c": 0.0, "k": 0.0, "theta0": -1.6}
    hi = {"rho_d": 1.0, "rho_s": 100.0, "alpha": 2.0, "p": 5.0, "f0": 20.0, "f1": 20.0, "kap": 1e39,
          "lambda": 1e8, "c": 1e39, "k": 1e3, "theta0": 1.6}

    def starts(data):
        return [x for _, x in sgd]

    return Model(name="sgd", label="SGD (Bagher et al. 2012)",
                 parameters=[f"{n}_{c}" for c in "rgb" for n in SGD_PARAMETERS],
                 lower=np.array([lo[n] for _ in range(3) for n in SGD_PARAMETERS]),
                 upper=np.array([hi[n] for _ in range(3) for n in SGD_PARAMETERS]),
                 eval_cos=sgd_eval_cos, starts=starts, free=free, max_nfev=200,
                 log=tuple(f"alpha_{c}" for c in "rgb"), channel_eval_cos=sgd_channel,
                 notes="started from the best three of the 100 published MERL fits; kap, c, k kept from the start")


class RoughPlasticBasis:
    """Mitsuba's ``roughplastic`` (GGX, ``int_ior`` :data:`PLASTIC_IOR`, ``nonlinear`` false)
    as ``kd * diffuse(alpha) + ks * specular(alpha)``, both evaluated by the plugin at the fit's
    directions once per ``alpha`` (cached)."""

    def __init__(self):
        self._cache: dict[tuple[float, int], tuple[np.ndarray, np.ndarray]] = {}

    def basis(self, alpha: float, view, light) -> tuple[np.ndarray, np.ndarray]:
        from nbrdf_tools.common import compare_materials as cm
        import mitsuba as mi

        key = (float(alpha), id(view))
        if key not in self._cache:
            if len(self._cache) > 64:
                self._cache.clear()
            cm.set_variant()
            parts = []
            for kd, ks in ((1.0, 0.0), (0.0, 1.0)):
                bsdf = mi.load_dict(roughplastic_dict([kd] * 3, ks, alpha))
                parts.append(cm.eval_cos(bsdf, view, light)[0])
            self._cache[key] = (parts[0], parts[1])
        return self._cache[key]

    def eval_cos(self, x, view, light) -> np.ndarray:
        diffuse, specular = self.basis(float(x[4]), view, light)
        return np.asarray(x[:3])[:, None] * diffuse[None, :] + float(x[3]) * specular[None, :]


def roughplastic_dict(kd, ks: float, alpha: float) -> dict:
    return {"type": "roughplastic", "distribution": "ggx", "alpha": float(alpha), "int_ior": PLASTIC_IOR,
            "nonlinear": False, "diffuse_reflectance": {"type": "rgb", "value": [float(c) for c in kd]},
            "specular_reflectance": {"type": "rgb", "value": [float(ks)] * 3}}


def roughconductor_dict(x) -> dict:
    """Mitsuba's GGX ``roughconductor`` (``material none``) of ``(R_rgb, alpha)`` or, anisotropic,
    ``(R_rgb, alpha_u, alpha_v)``."""
    alphas = {"alpha": float(x[3])} if len(x) == 4 else {"alpha_u": float(x[3]), "alpha_v": float(x[4])}
    return {"type": "roughconductor", "distribution": "ggx", "material": "none", **alphas,
            "specular_reflectance": {"type": "rgb", "value": [float(c) for c in x[:3]]}}


def roughplastic_model() -> Model:
    basis = RoughPlasticBasis()

    def starts(data):
        kd = _reflectance_scale(data)
        return [[kd, kd, kd, 0.9, a] for a in (0.02, 0.08, 0.3)]

    return Model(name="roughplastic", label="GGX `roughplastic`",
                 parameters=["diffuse_reflectance_r", "diffuse_reflectance_g", "diffuse_reflectance_b",
                             "specular_reflectance", "alpha"],
                 lower=np.array([0.0, 0.0, 0.0, 0.0, 1e-3]), upper=np.array([1.0, 1.0, 1.0, 1.0, 1.0]),
                 eval_cos=basis.eval_cos, starts=starts, max_nfev=200, log=("alpha",),
                 notes=f"int_ior {PLASTIC_IOR} fixed, nonlinear false, reflectances in [0, 1] (Mitsuba rejects more); "
                       "evaluated by Mitsuba's plugin")


MODELS: dict[str, Callable[[], Model]] = {
    "roughconductor": ggx_conductor_model,
    "roughconductor_aniso": ggx_aniso_conductor_model,
    "roughplastic": roughplastic_model,
    "blinn_phong": blinn_phong_model,
    "abc": abc_model,
    "sgd": sgd_model,
}
# Stored parameters per model (float32 each): what a scene file or shader holds.
STORED_PARAMETERS = {"roughconductor": 4, "roughconductor_aniso": 5, "roughplastic": 6, "blinn_phong": 7, "abc": 9,
                     "sgd": 33}


# --------------------------------------------------------------------------------------------
# Mitsuba BSDFs of the fits


def mitsuba_bsdf(model: str, x):
    """A Mitsuba BSDF of a fit: the plugin itself for roughconductor/roughplastic, else a
    :class:`NumpyBSDF` (eval only) of the NumPy form."""
    import mitsuba as mi

    if model in ("roughconductor", "roughconductor_aniso"):
        return mi.load_dict(roughconductor_dict(x))
    if model == "roughplastic":
        return mi.load_dict(roughplastic_dict(x[:3], x[3], x[4]))
    forms = {"blinn_phong": blinn_phong_eval_cos, "abc": abc_eval_cos, "sgd": sgd_eval_cos}
    return numpy_bsdf(forms[model], np.asarray(x, np.float64), model)


_NUMPY_BSDF_CLASS = None


def numpy_bsdf(eval_cos: Callable, x: np.ndarray, name: str):
    """A ``mi.BSDF`` whose ``eval`` is ``eval_cos(x, si.wi, wo)`` on NumPy arrays: eval only,
    for direct (wavefront) calls such as :func:`nbrdf_tools.common.compare_materials.render_spheres`,
    not inside Mitsuba's symbolic rendering loops."""
    global _NUMPY_BSDF_CLASS
    import drjit as dr
    import mitsuba as mi

    if _NUMPY_BSDF_CLASS is None:
        class NumpyBSDF(mi.BSDF):
            def __init__(self, props):
                super().__init__(props)
                self.m_flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.DiffuseReflection
                self.m_components = [self.m_flags]

            def eval(self, ctx, si, wo, active=True):
                view = np.array(si.wi, dtype=np.float64).reshape(3, -1)
                light = np.array(wo, dtype=np.float64).reshape(3, -1)
                value = self.form(self.x, view, light)
                return mi.Color3f(np.ascontiguousarray(value, dtype=np.float32))

            def sample(self, ctx, si, sample1, sample2, active=True):
                raise NotImplementedError("NumpyBSDF evaluates only")

            def pdf(self, ctx, si, wo, active=True):
                return dr.zeros(mi.Float, dr.width(wo))

            def to_string(self):
                return f"NumpyBSDF[{self.name}]"

        _NUMPY_BSDF_CLASS = NumpyBSDF
    bsdf = _NUMPY_BSDF_CLASS(mi.Properties())
    bsdf.form, bsdf.x, bsdf.name = eval_cos, x, name
    return bsdf
