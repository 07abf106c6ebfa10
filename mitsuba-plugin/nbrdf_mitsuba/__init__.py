"""Neural BRDFs (Sztrajman et al., CGF 2021) and MERL tables as Mitsuba 3 BSDFs.

``import nbrdf_mitsuba`` registers the BSDF plugins ``nbrdf`` and ``merl`` with Mitsuba: now for
the current variant if one is set, and again whenever ``mi.set_variant`` switches variants.
:func:`register` does the same by hand and may be called any number of times.

Import it **before** ``mitsuba``/``drjit`` when you use the ``llvm_*`` variants: Dr.Jit picks its
libLLVM once, at its first import, and this package points it at a libLLVM >= 16
(``DRJIT_LIBLLVM_PATH``) when the variable is unset; see :mod:`nbrdf_mitsuba._llvm`.

Example::

    import nbrdf_mitsuba
    import mitsuba as mi
    mi.set_variant("llvm_ad_rgb")
    bsdf = mi.load_dict({"type": "nbrdf", "filename": "gold-metallic-paint.nbrdf.json"})
"""

from __future__ import annotations

from . import _llvm

_llvm.configure()  # must precede the first import of drjit

import mitsuba as mi  # noqa: E402

__version__ = "0.1.0"
PLUGINS = ("nbrdf", "merl")

_registered: set[str] = set()


def register(variant: str | None = None) -> bool:
    """Registers the ``nbrdf`` and ``merl`` BSDFs for the current Mitsuba variant.

    Idempotent per variant; Dr.Jit's flags are left alone (the default ``jit`` backend traces
    into Mitsuba's symbolic kernels; ``backend="rust"`` in a JIT variant runs the library only
    in wavefront mode, see :func:`use_wavefront_mode`, and its traced twin elsewhere). Returns
    False when no variant is set (nothing to register for yet).
    """
    variant = variant or mi.variant()
    if variant is None:
        return False
    if variant != mi.variant():
        raise ValueError(f"register({variant!r}): the current Mitsuba variant is {mi.variant()!r}")
    from . import bsdf

    if variant not in _registered:
        nbrdf_cls, merl_cls = bsdf.classes()
        mi.register_bsdf("nbrdf", lambda props: nbrdf_cls(props))
        mi.register_bsdf("merl", lambda props: merl_cls(props))
        _registered.add(variant)
    return True


def _on_variant_change(old, new) -> None:
    # Runs inside mi.set_variant: a broken plugin installation must not break Mitsuba itself,
    # so failures become warnings here (an explicit register() call raises them).
    if new is not None:
        try:
            register(new)
        except Exception as error:  # noqa: BLE001
            import warnings

            warnings.warn(f"nbrdf_mitsuba: could not register the nbrdf/merl BSDFs for {new}: {error}",
                          stacklevel=2)


def _install_variant_hook() -> bool:
    detail = getattr(mi, "detail", None)
    add = getattr(detail, "add_variant_callback", None)
    if add is None:
        return False
    add(_on_variant_change)
    return True


_install_variant_hook()
register()


def __getattr__(name):
    # Lazy access to the native layer, so that `python -m nbrdf_mitsuba.import_keras` works
    # without loading the library.
    if name in ("use_wavefront_mode", "set_default_backend"):
        from . import bsdf

        return getattr(bsdf, name)
    if name in ("NbrdfError", "version"):
        from . import _native

        return getattr(_native, name)
    if name == "llvm":
        import importlib

        return importlib.import_module(f"{__name__}.llvm")
    raise AttributeError(f"module 'nbrdf_mitsuba' has no attribute {name!r}")


__all__ = ["register", "use_wavefront_mode", "set_default_backend", "PLUGINS", "NbrdfError", "llvm"]
