"""Independent NumPy references and helpers for the plugin tests.

Everything here is written from docs/design.md (sections 2-4 and 6) in float64 NumPy, without
calling the Rust code, so that the tests compare two implementations. These are the deliberate
second copies of the Rust formulas; docs/design.md's twin table ("Twins") names each one's Rust
twin and the test that holds the two together. The network's input and forward pass are not
repeated here: they are ``nbrdf_tools.common.network``'s (the one NumPy copy, shared with the tools).

``to_angles`` / ``from_angles``, ``merl_trilinear`` and ``nbrdf_reference`` take planar (3, n)
batches in their historical ``(light, view)`` order (the Rust API, ``nbrdf_tools.common.network`` and
the Mitsuba wrappers below (``bsdf_eval`` and friends) take ``(view, light)``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nbrdf_tools.common import network
from nbrdf_tools.common.network import apply, rot_y, rot_z

N_TH, N_TD, N_PD = 90, 90, 180
CELLS = N_TH * N_TD * N_PD
SCALE = np.array([1.0 / 1500.0, 1.15 / 1500.0, 1.66 / 1500.0])
HALF_PI = np.pi / 2


# ---------------------------------------------------------------------------------------------
# Directions


CURRENT_BACKEND = "rust"  # set by the `variant` fixture


def current_backend() -> str:
    return CURRENT_BACKEND


def float32_rtol(rust_rtol: float) -> float:
    """The traced backend computes angles in float32 (the Rust one in float64), which moves
    table lookups by a few float32 ulps of the continuous index: allow 1e-4 there."""
    return rust_rtol if CURRENT_BACKEND == "rust" else max(rust_rtol, 1e-4)


def sph(theta, phi) -> np.ndarray:
    """Planar (3, n) unit directions from polar angle ``theta`` and azimuth ``phi``."""
    theta, phi = np.broadcast_arrays(np.asarray(theta, float), np.asarray(phi, float))
    return np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])


def normalize(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=0, keepdims=True)


def random_pairs(n: int, seed: int, min_cos: float = 0.02) -> tuple[np.ndarray, np.ndarray]:
    """(view, light), uniform on the hemisphere above ``min_cos``."""
    rng = np.random.default_rng(seed)
    def draw():
        return sph(np.arccos(rng.uniform(min_cos, 1.0, n)), rng.uniform(-np.pi, np.pi, n))
    return draw(), draw()


def grazing_pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(view, light) with at least one direction within ~3 degrees of the horizon."""
    rng = np.random.default_rng(seed)
    grazing = sph(rng.uniform(np.radians(87.0), np.radians(89.9), n), rng.uniform(-np.pi, np.pi, n))
    other = sph(np.arccos(rng.uniform(0.0, 1.0, n)), rng.uniform(-np.pi, np.pi, n))
    swap = rng.uniform(size=n) < 0.5
    view = np.where(swap, grazing, other)
    light = np.where(swap, other, grazing)
    return view, light


def f32(a: np.ndarray) -> np.ndarray:
    """Rounds to float32 (what Mitsuba passes) and back to float64 for the reference."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


# ---------------------------------------------------------------------------------------------
# Rusinkiewicz coordinates (docs/design.md section 2), with trigonometry and rotation matrices


def to_angles(light: np.ndarray, view: np.ndarray):
    """(theta_h, phi_h, theta_d, phi_d, d) of planar light/view directions (``d`` planar too)."""
    theta_h, phi_h, theta_d, phi_d, d = network.rusinkiewicz(np.asarray(view).T, np.asarray(light).T)
    return theta_h, phi_h, theta_d, phi_d, d.T


def from_angles(theta_h, phi_h, theta_d, phi_d):
    """(light, view): ``l = R_z(phi_h) R_y(theta_h) d``, ``v = 2 (l . h) h - l``."""
    theta_h, phi_h, theta_d, phi_d = np.broadcast_arrays(*(np.asarray(a, float) for a in (theta_h, phi_h, theta_d, phi_d)))
    d = sph(theta_d, phi_d)
    l = apply(rot_z(phi_h), apply(rot_y(theta_h), d))
    h = sph(theta_h, phi_h)
    v = 2 * np.sum(l * h, axis=0) * h - l
    return l, v


# ---------------------------------------------------------------------------------------------
# MERL tables (docs/design.md section 3)


def write_merl(path: Path, stored: np.ndarray | None = None, analytic: bool = False) -> Path:
    """Writes a MERL-format file; ``stored`` is (3, 90, 90, 180) as stored (unscaled)."""
    if stored is None:
        stored = analytic_table()
    stored = np.asarray(stored, dtype="<f8").reshape(3, CELLS)
    with open(path, "wb") as f:
        f.write(np.array([N_TH, N_TD, N_PD], dtype="<i4").tobytes())
        f.write(stored.tobytes())
    return Path(path)


def read_merl(path: Path) -> np.ndarray:
    """Stored (unscaled) values, shape (3, 90, 90, 180) = (channel, theta_h, theta_d, phi_d)."""
    raw = Path(path).read_bytes()
    header = np.frombuffer(raw[:12], dtype="<i4")
    assert tuple(header) == (N_TH, N_TD, N_PD), header
    return np.frombuffer(raw[12:], dtype="<f8").reshape(3, N_TH, N_TD, N_PD)


def cell_centre_angles(i_th, i_td, i_pd):
    """Angles at continuous index i + 0.5 on each axis."""
    u = (np.asarray(i_th) + 0.5) / N_TH
    return u * u * HALF_PI, (np.asarray(i_td) + 0.5) / N_TD * HALF_PI, (np.asarray(i_pd) + 0.5) / N_PD * np.pi


def analytic_table() -> np.ndarray:
    """A smooth Blinn-Phong-like table: the fallback when the `nbrdf` CLI is not built."""
    i_th, i_td, i_pd = np.meshgrid(np.arange(N_TH), np.arange(N_TD), np.arange(N_PD), indexing="ij")
    th, td, pd = cell_centre_angles(i_th, i_td, i_pd)
    kd = np.array([0.15, 0.1, 0.05]) / np.pi
    ks = np.array([0.5, 0.45, 0.3]) * (60 + 2) / (2 * np.pi)
    lobe = np.cos(th) ** 60 * (1 + 0.1 * np.cos(pd)) * (1 + 0.2 * np.sin(td))
    f = kd[:, None, None, None] + ks[:, None, None, None] * lobe
    return f / SCALE[:, None, None, None]


def continuous_index(theta_h, theta_d, phi_d):
    phi = np.where(phi_d < 0, phi_d + np.pi, phi_d)
    phi = np.where(phi >= np.pi, phi - np.pi, phi)
    return (N_TH * np.sqrt(np.maximum(theta_h, 0) / HALF_PI), N_TD * theta_d / HALF_PI, N_PD * phi / np.pi)


def merl_trilinear(stored: np.ndarray, light: np.ndarray, view: np.ndarray) -> np.ndarray:
    """Reference f_r (3, n): trilinear between cell centres (index i + 0.5), clamped at the theta
    borders, wrapping in phi_d; invalid cells (any channel < 0) skipped with renormalised
    weights; zero-weight corners ignored; all invalid -> 0."""
    theta_h, _, theta_d, phi_d, _ = to_angles(light, view)
    xh, xd, xp = continuous_index(theta_h, theta_d, phi_d)

    def clamped(x, n):
        x = np.clip(x - 0.5, 0.0, n - 1.0)
        i0 = np.minimum(np.floor(x).astype(int), n - 1)
        i1 = np.minimum(i0 + 1, n - 1)
        return i0, i1, x - i0

    def wrapped(x, n):
        x = x - 0.5
        f = np.floor(x)
        i0 = f.astype(int) % n
        return i0, (i0 + 1) % n, x - f

    h0, h1, wh = clamped(xh, N_TH)
    d0, d1, wd = clamped(xd, N_TD)
    p0, p1, wp = wrapped(xp, N_PD)
    values = stored * SCALE[:, None, None, None]
    valid_cell = np.all(stored >= 0, axis=0)
    total = np.zeros((3, len(xh)))
    weight_sum = np.zeros(len(xh))
    for ih, w_h in ((h0, 1 - wh), (h1, wh)):
        for id_, w_d in ((d0, 1 - wd), (d1, wd)):
            for ip, w_p in ((p0, 1 - wp), (p1, wp)):
                w = w_h * w_d * w_p
                use = (w > 0) & valid_cell[ih, id_, ip]
                w = np.where(use, w, 0.0)
                total += w * values[:, ih, id_, ip]
                weight_sum += w
    return np.where(weight_sum > 0, total / np.where(weight_sum > 0, weight_sum, 1), 0.0)


# ---------------------------------------------------------------------------------------------
# The NBRDF network (docs/design.md section 4), read from the Keras file with h5py


def random_layers(hidden: int = 21, seed: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """float32 weights of a random, smooth network (a stand-in when no trained one is at hand)."""
    rng = np.random.default_rng(seed)
    layers = [(rng.uniform(-0.5, 0.5, s).astype(np.float32), rng.uniform(-0.1, 0.1, s[1]).astype(np.float32))
              for s in [(6, hidden), (hidden, hidden)]]
    # A positive last layer keeps f_r > 0 everywhere, as for a real material (Mitsuba's chi^2
    # adapter counts zero-weight samples as failures).
    layers.append((rng.uniform(0.0, 0.3, (hidden, 3)).astype(np.float32), np.full(3, 0.5, np.float32)))
    return layers


def write_network(path: Path, layers=None, sampling: dict | None = None, name: str = "synthetic",
                  anisotropic: bool = False) -> Path:
    """Writes an ``*.nbrdf.json`` file (docs/design.md section 4); an anisotropic one is version 2."""
    import json

    layers = random_layers() if layers is None else layers
    document = {
        "format": "nbrdf", "version": 2 if anisotropic else 1, "name": name,
        "layers": [{"inputs": int(w.shape[0]), "outputs": int(w.shape[1]),
                    "weights": [float(v) for v in np.asarray(w, np.float32).ravel()],
                    "bias": [float(v) for v in np.asarray(b, np.float32)]} for w, b in layers],
        "provenance": {"source": "nbrdf tests"},
    }
    if anisotropic:
        document["anisotropic"] = True
    if sampling is not None:
        document["sampling"] = sampling
    Path(path).write_text(json.dumps(document))
    return Path(path)


def read_network_layers(path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    """(W, b) pairs of an ``*.nbrdf.json`` file, float64."""
    return network.read_layers(path)


def keras_layers(h5_path: Path) -> list[tuple[np.ndarray, np.ndarray]]:
    import h5py

    with h5py.File(h5_path, "r") as f:
        return [(np.asarray(f[f"dense_{k}/dense_{k}/kernel:0"], np.float64),
                 np.asarray(f[f"dense_{k}/dense_{k}/bias:0"], np.float64)) for k in (1, 2, 3)]


def network_input(light: np.ndarray, view: np.ndarray, anisotropic: bool = False) -> np.ndarray:
    """(n, 6) network input of planar directions (``nbrdf_tools.common.network.network_input``)."""
    return network.network_input(np.asarray(view).T, np.asarray(light).T, anisotropic)


def nbrdf_reference(layers, light: np.ndarray, view: np.ndarray, anisotropic: bool = False) -> np.ndarray:
    """f_r cos(theta_l), (3, n), float64; zero when either direction is below the horizon."""
    f = network.evaluate(layers, np.asarray(view).T, np.asarray(light).T, anisotropic).T
    cos_l = normalize(light)[2]
    above = (normalize(light)[2] > 0) & (normalize(view)[2] > 0)
    return np.where(above, f * cos_l, 0.0)


# ---------------------------------------------------------------------------------------------
# Blinn-Phong mixture pdf (docs/design.md section 6)


def phong_pdf(view: np.ndarray, light: np.ndarray, exponent: float, weight: float) -> np.ndarray:
    v, l = normalize(view), normalize(light)
    h = normalize(v + l)
    cos_h = np.clip(h[2], 0, 1)
    spec = (exponent + 1) / (2 * np.pi) * cos_h ** exponent / (4 * np.abs(np.sum(v * h, axis=0)))
    diff = np.maximum(l[2], 0) / np.pi
    return np.where(l[2] > 0, weight * spec + (1 - weight) * diff, 0.0)


# ---------------------------------------------------------------------------------------------
# Calling a Mitsuba BSDF on planar NumPy batches, in scalar and JIT variants


def _mi():
    import drjit as dr
    import mitsuba as mi

    return mi, dr


def _si(view_cols):
    mi, dr = _mi()
    si = dr.zeros(mi.SurfaceInteraction3f, view_cols.shape[1])
    si.wi = mi.Vector3f(np.ascontiguousarray(view_cols, dtype=np.float32))
    return si


def _scalar_si(v):
    mi, dr = _mi()
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(*map(float, v))
    return si


def is_jit() -> bool:
    mi, dr = _mi()
    return dr.is_jit_v(mi.Float)


def bsdf_eval(bsdf, view, light, ctx=None) -> np.ndarray:
    mi, dr = _mi()
    ctx = ctx or mi.BSDFContext()
    if is_jit():
        out = bsdf.eval(ctx, _si(view), mi.Vector3f(np.ascontiguousarray(light, dtype=np.float32)))
        return np.asarray(out.numpy(), dtype=np.float64).reshape(3, -1)
    return np.stack([np.asarray(bsdf.eval(ctx, _scalar_si(view[:, i]), mi.Vector3f(*map(float, light[:, i]))),
                                dtype=np.float64) for i in range(view.shape[1])], axis=1).reshape(3, -1)


def bsdf_pdf(bsdf, view, light, ctx=None) -> np.ndarray:
    mi, dr = _mi()
    ctx = ctx or mi.BSDFContext()
    if is_jit():
        out = bsdf.pdf(ctx, _si(view), mi.Vector3f(np.ascontiguousarray(light, dtype=np.float32)))
        return np.asarray(out.numpy(), dtype=np.float64).reshape(-1)
    return np.array([float(bsdf.pdf(ctx, _scalar_si(view[:, i]), mi.Vector3f(*map(float, light[:, i]))))
                     for i in range(view.shape[1])])


def bsdf_eval_pdf(bsdf, view, light, ctx=None):
    mi, dr = _mi()
    ctx = ctx or mi.BSDFContext()
    if is_jit():
        value, pdf = bsdf.eval_pdf(ctx, _si(view), mi.Vector3f(np.ascontiguousarray(light, dtype=np.float32)))
        return np.asarray(value.numpy(), np.float64).reshape(3, -1), np.asarray(pdf.numpy(), np.float64).reshape(-1)
    values, pdfs = [], []
    for i in range(view.shape[1]):
        value, pdf = bsdf.eval_pdf(ctx, _scalar_si(view[:, i]), mi.Vector3f(*map(float, light[:, i])))
        values.append(np.asarray(value, np.float64))
        pdfs.append(float(pdf))
    return np.stack(values, axis=1).reshape(3, -1), np.array(pdfs)


def bsdf_sample(bsdf, view, u, ctx=None):
    """(wo (3, n), weight (3, n), pdf (n,), sampled_type (n,)) for uniforms ``u`` (3, n)."""
    mi, dr = _mi()
    ctx = ctx or mi.BSDFContext()
    u = np.asarray(u, dtype=np.float32)
    if is_jit():
        bs, weight = bsdf.sample(ctx, _si(view), mi.Float(u[0]), mi.Point2f(np.ascontiguousarray(u[1:])))
        return (np.asarray(bs.wo.numpy(), np.float64).reshape(3, -1), np.asarray(weight.numpy(), np.float64).reshape(3, -1),
                np.asarray(bs.pdf.numpy(), np.float64).reshape(-1),
                np.broadcast_to(np.asarray(bs.sampled_type.numpy()).reshape(-1), (view.shape[1],)))
    wos, weights, pdfs, types = [], [], [], []
    for i in range(view.shape[1]):
        bs, weight = bsdf.sample(ctx, _scalar_si(view[:, i]), float(u[0, i]), mi.Point2f(float(u[1, i]), float(u[2, i])))
        wos.append(np.asarray(bs.wo, np.float64))
        weights.append(np.asarray(weight, np.float64))
        pdfs.append(float(bs.pdf))
        types.append(int(bs.sampled_type))
    return np.stack(wos, axis=1), np.stack(weights, axis=1), np.array(pdfs), np.array(types)
