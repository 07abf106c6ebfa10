"""Spatially varying materials in the ``nbrdf`` BSDF: a file of format version 4, a decoder
network and a latent texture (docs/textured.md; the files: docs/formats.md). A file with a
``spectral`` object is a spectral material: its decoder gives B-spline coefficients, evaluated
per wavelength in spectral variants (:mod:`nbrdf_mitsuba.textured_backends`).

The library loads and checks the file and is the reference (the ``rust`` backend, at
``si.uv``). The traced twin (the ``jit`` backend, :mod:`nbrdf_mitsuba.jit.textured`) needs the
decoder's weights and the texture's values, which the C ABI does not hand out: once the library
has accepted the file, :func:`read_parts` reads the JSON again and :func:`read_texture` the
OpenEXR texture (through Mitsuba's ``Bitmap``).

With the ``jit`` backend, ``traverse`` exposes ``latent`` (the latent codes, a ``mi.TensorXf``
of height x width x C, differentiable), ``lobes`` (the lobe channels, height x width x 2 per
lobe, when the file stores lobes) and ``weights`` (the decoder's W1 b1 W2 b2 ... as one
``mi.Float``, differentiable with ``jit_weights`` = ``opaque``, as a homogeneous network's). The
names have no dot: ``SceneParameters`` reads a dot as a child object's name. Updates are
validated as a whole (shapes, finite values) and applied atomically, as for homogeneous
networks.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from . import jit
from .backends import prepare_variant
from .jit.textured import TracedTexturedMaterial, TracedUvMapping
from .textured_backends import TexturedJitBackend, TexturedRustBackend
from .validation import non_finite_name

#: The ``nbrdf`` parameters of homogeneous networks only: a spatially varying material samples
#: the lobes its texture stores.
HOMOGENEOUS_ONLY = ("sampling", "exponent", "specular_weight", "exponent2", "specular_weight2", "exponent_v")
#: The traversed keys.
LATENT, LOBES, WEIGHTS = "latent", "lobes", "weights"


@dataclass
class TexturedParts:
    """What a version-4 file says (docs/formats.md), after the library has checked it."""

    name: str
    anisotropic: bool
    layers: list  # [(W (inputs, outputs), b (outputs,)) float32]
    channels: int
    lobe_channels: list  # exponent and weight channel names, lobe by lobe
    width: int
    height: int
    wrap: str
    filter: str
    to_uv: list  # 3 rows of 3
    texture: Path

    @property
    def lobes(self) -> int:
        return len(self.lobe_channels) // 2

    @property
    def channel_names(self) -> list[str]:
        return [f"latent.{k}" for k in range(self.channels)] + list(self.lobe_channels)

    @property
    def hidden_width(self) -> int:
        """The widest hidden layer (what the traced backend's cost grows with)."""
        return max((int(W.shape[1]) for W, _ in self.layers[:-1]), default=0)

    def shapes(self) -> str:
        return " -> ".join(str(n) for n in [self.layers[0][0].shape[0], *(W.shape[1] for W, _ in self.layers)])


def read_parts(path: str) -> TexturedParts:
    """The decoder and the texture's description of a file the library has loaded."""
    document = json.loads(Path(path).read_text(encoding="utf-8"))
    latent = document["latent"]
    layers = [(np.asarray(layer["weights"], np.float32).reshape(layer["inputs"], layer["outputs"]),
               np.asarray(layer["bias"], np.float32)) for layer in document["layers"]]
    lobes = (document.get("sampling") or {}).get("lobes", [])
    texture = Path(path).parent / latent["path"]
    return TexturedParts(
        name=document.get("name", ""), anisotropic=bool(document.get("anisotropic", False)), layers=layers,
        channels=int(latent["channels"]), lobe_channels=[name for lobe in lobes for name in (lobe["exponent"],
                                                                                             lobe["weight"])],
        width=int(latent["width"]), height=int(latent["height"]), wrap=latent.get("wrap", "repeat"),
        filter=latent.get("filter", "bilinear"), to_uv=latent.get("to_uv", np.eye(3).tolist()), texture=texture)


def read_texture(parts: TexturedParts) -> np.ndarray:
    """The texture as float32 (height, width, channels), channels in ``parts.channel_names``
    order (the file's order is alphabetical). Raises where Mitsuba reads another size or other
    channels than the library did."""
    bitmap = mi.Bitmap(str(parts.texture))
    names = [channel.name for channel in bitmap.struct_()]
    values = np.asarray(bitmap).astype(np.float32).reshape(parts.height, parts.width, -1)
    if sorted(names) != sorted(parts.channel_names):
        raise RuntimeError(f'"{parts.texture}": Mitsuba reads the channels {", ".join(names)}, expected '
                           f'{", ".join(parts.channel_names)}')
    return np.ascontiguousarray(values[..., [names.index(name) for name in parts.channel_names]])


class TexturedMaterial:
    """The state of an ``nbrdf`` BSDF whose file is spatially varying: its backend
    (``bsdf._backend``, set here), the traced twin and the traversed texture and weights.

    ``get(name)`` reads a scene parameter (None when absent); ``backend`` and ``jit_weights``
    are the requested ones. The BSDF's ``_type_name``, ``_filename``, ``_path``, ``_native``,
    ``_arrays`` and ``_choose_backend`` are used while it is built; no reference to it is kept."""

    def __init__(self, bsdf, get, backend: str, jit_weights: str):
        bsdf._textured = self  # the BSDF's _traced_width_problem reads hidden_width
        self.label = f'{bsdf._type_name()} "{bsdf._filename}"'
        asked = [f'"{name}"' for name in HOMOGENEOUS_ONLY if get(name) is not None]
        if asked:
            raise ValueError(f"{self.label}: {', '.join(asked)} {'is a parameter' if len(asked) == 1 else 'are parameters'} "
                             "of homogeneous networks only; this file is a spatially varying material (format "
                             "version 4), which samples the Blinn-Phong lobes its latent texture stores")
        self.native, self.arrays, self.filename = bsdf._native, bsdf._arrays, bsdf._filename
        self.parts = read_parts(bsdf._path)
        #: A spectral material's ``(count, min_nm, max_nm, M)`` (a file with a ``spectral``
        #: object), else None.
        self.spectral = bsdf._spectral_output()
        self.hidden_width = self.parts.hidden_width
        flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.SpatiallyVarying
        if self.parts.anisotropic:
            flags = flags | mi.BSDFFlags.Anisotropic
        bsdf.m_components = [flags]
        bsdf.m_flags = flags
        name = bsdf._choose_backend(backend)
        prepare_variant(self.arrays, bsdf._type_name())
        self.traced, twin = None, None
        too_wide = bsdf._traced_width_problem() if self.arrays.wavefront else None
        if self.arrays.wavefront and (name == "jit" or not too_wide):
            self.traced = self._trace(jit_weights if name == "jit" else "literal")
            twin = TexturedJitBackend(self.traced, self.spectral)
        self.backend = twin if name == "jit" else TexturedRustBackend(self.native, self.spectral, self.arrays, twin,
                                                                      self.label, too_wide if twin is None else None)
        bsdf._backend = self.backend

    def _trace(self, mode: str) -> TracedTexturedMaterial:
        mode = str(mode).strip().lower()
        if mode not in jit.WEIGHT_MODES:
            raise ValueError(f'{self.label}: unknown jit_weights "{mode}" (expected one of: {", ".join(jit.WEIGHT_MODES)})')
        texture = read_texture(self.parts)
        channels = self.parts.channels
        #: The traversed texture (updated in place by SceneParameters) and its last good values.
        self.latent = mi.TensorXf(np.ascontiguousarray(texture[..., :channels]))
        self.lobe_values = mi.TensorXf(np.ascontiguousarray(texture[..., channels:])) if self.parts.lobes else None
        self.good = {LATENT: texture[..., :channels].copy(), LOBES: texture[..., channels:].copy()}
        decoder = jit.TracedNetwork(self.parts.layers, weights=mode, anisotropic=self.parts.anisotropic)
        mapping = TracedUvMapping(self.parts.width, self.parts.height, self.parts.wrap, self.parts.filter,
                                  self.parts.to_uv)
        return TracedTexturedMaterial(decoder, mapping, channels, self.parts.lobes, lambda: self.latent,
                                      lambda: self.lobe_values)

    # -- traverse and updates -------------------------------------------------------------------

    def traverse(self, put) -> None:
        """The texture and the decoder's weights (``jit`` backend only: the library's material
        is immutable)."""
        if self.backend.name != "jit":
            return
        put(LATENT, self.latent, mi.ParamFlags.Differentiable)
        if self.lobe_values is not None:
            # The sampling lobes: updatable, but a discrete choice of directions has no gradient.
            put(LOBES, self.lobe_values, mi.ParamFlags.NonDifferentiable)
        decoder = self.traced.decoder
        differentiable = decoder.mode == "opaque"
        put(WEIGHTS, decoder.flat, mi.ParamFlags.Differentiable if differentiable else mi.ParamFlags.NonDifferentiable)

    def parameters_changed(self, keys=None) -> None:
        """Validates the whole update (shapes; finite texture values and weights), then applies
        all of it or nothing: a rejected update raises ValueError, writes the last good values
        back into the traversed parameters and leaves the BSDF as it was."""
        if self.backend.name != "jit":
            return
        named = (lambda key: True) if keys is None else (lambda key: any(str(k).rsplit(".", 1)[-1] == key for k in keys))
        try:
            weights = self._validated_weights() if named(WEIGHTS) else None
            textures = {key: self._validated_texture(key) for key in (LATENT, LOBES)
                        if named(key) and self._tensor(key) is not None}
        except ValueError as error:
            self._restore()
            raise ValueError(f"{self.label}: update rejected, the BSDF keeps its previous parameters: {error}") from None
        if weights is not None:
            self.traced.decoder.refresh()
        self.good.update(textures)

    def _tensor(self, key):
        return self.latent if key == LATENT else self.lobe_values

    def _validated_weights(self):
        decoder = self.traced.decoder
        count = dr.width(decoder.flat)
        if count != decoder.parameter_count:
            raise ValueError(f'"{WEIGHTS}" must hold {decoder.parameter_count} values, got {count}')
        values = np.asarray(dr.detach(decoder.flat).numpy(), dtype=np.float32).reshape(-1)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            k = int(bad[0])
            raise ValueError(f'"{WEIGHTS}" value {k} ({decoder.describe_index(k)}) is {non_finite_name(values[k])}; '
                             f"{bad.size} of {values.size} weights are not finite (every weight must be a finite float32)")
        return values

    def _validated_texture(self, key) -> np.ndarray:
        expected = self.good[key].shape
        shape = tuple(dr.shape(self._tensor(key)))
        if shape != expected:
            raise ValueError(f'"{key}" has shape {shape}, expected {expected} (height x width x channels of the '
                             "file's texture)")
        values = np.asarray(dr.detach(self._tensor(key)).numpy(), dtype=np.float32)
        bad = np.argwhere(~np.isfinite(values))
        if bad.size:
            y, x, k = (int(i) for i in bad[0])
            raise ValueError(f'"{key}" texel (x {x}, y {y}) channel {k} is {non_finite_name(values[y, x, k])}; '
                             f"{len(bad)} values are not finite (updates must be finite: a file may hold "
                             "non-finite texels, which render as 0)")
        return values

    def _restore(self) -> None:
        decoder = self.traced.decoder
        if not np.array_equal(np.asarray(dr.detach(decoder.flat).numpy()).reshape(-1), decoder.good):
            mi.set_property(decoder.flat, type(decoder.flat)(decoder.good))
        for key in (LATENT, LOBES):
            tensor = self._tensor(key)
            if tensor is not None:
                mi.set_property(tensor, mi.TensorXf(self.good[key]))

    # -- description ----------------------------------------------------------------------------

    def to_string(self, class_name: str) -> str:
        parts = self.parts
        to_uv = "identity" if np.array_equal(parts.to_uv, np.eye(3)) else str(
            [[float(x) for x in row] for row in parts.to_uv])
        lobes = {0: "cosine", 1: "one Blinn-Phong lobe and cosine", 2: "two Blinn-Phong lobes and cosine"}[parts.lobes]
        lines = [f'filename = "{self.filename}"', "kind = spatially varying (format version 4)", f'name = "{parts.name}"',
                 f"latent_channels = {parts.channels}", f"texture_size = {parts.width} x {parts.height}",
                 f"mapping = wrap {parts.wrap}, filter {parts.filter}, to_uv {to_uv}",
                 f"decoder = {parts.shapes()}", f"anisotropic = {str(parts.anisotropic).lower()}",
                 f"sampling = texture lobes ({lobes})", f"backend = {self.backend.name}"]
        if self.spectral is not None:
            count, min_nm, max_nm, _ = self.spectral
            lines.insert(6, f"spectral = cubic B-spline, {count} coefficients over {min_nm:g}-{max_nm:g} nm")
        if self.backend.name == "jit":
            lines.append(f"jit_weights = {self.traced.decoder.mode}")
        return f"{class_name}[\n" + ",\n".join("  " + line for line in lines) + "\n]"
