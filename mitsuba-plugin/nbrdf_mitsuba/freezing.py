"""What Dr.Jit's frozen functions (``dr.freeze``) need from a BSDF written in Python: every Dr.Jit
array its traced code reads, found when Dr.Jit traverses the BSDF (:class:`JitState`).

Dr.Jit traverses a Python BSDF through the values of its ``__dict__``: arrays, lists, tuples, dicts,
dataclasses and ``DRJIT_STRUCT`` classes, but not plain Python objects, so the arrays held by the
plugin's helpers (the traced network's rows, the sampling tables) were invisible to it, and
recording a render ended in "a virtual function call ... no such object instance was found in the
function's inputs". The arrays are collected at each traversal, not kept in a list: a list made at
an update would go stale at the next, and a replay would read the old arrays without a word.

What Dr.Jit 1.5 does not replay: a Python BSDF's gather from a buffer inside Mitsuba's symbolic
call reads, in every replay, the buffer the recording saw (a plain Python BSDF gathering from an
updated ``mi.Float`` shows it too). The plugin's tables (MERL, the tabulated sampler) never change
after loading, so their replays are right; a spatially varying material's textures are updated,
so such a BSDF refuses to be frozen (:class:`FreezingRefused`) rather than render old textures.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

#: How deep the collection follows the plugin's objects (theirs nest three or four levels).
MAX_DEPTH = 12


class FreezingRefused(RuntimeError):
    """A frozen function was asked to record a BSDF whose replays would be wrong."""


class JitState:
    """Exposes to Dr.Jit's traversal the arrays reachable from ``owner`` (a BSDF's ``__dict__``)
    through the plugin's own objects, lists, tuples and dicts, and the Mitsuba objects among them
    (an analytic base BSDF), which Dr.Jit traverses itself. A ``DRJIT_STRUCT`` whose one field is
    computed when read: Dr.Jit reads a struct's fields by name at each traversal."""

    DRJIT_STRUCT = {"arrays": list}

    def __init__(self, owner: dict, label: str):
        self._owner, self._label = owner, label

    @property
    def arrays(self) -> list:
        textured = self._owner.get("_textured")
        if textured is not None and textured.backend.name == "jit":
            raise FreezingRefused(f"{self._label}: a spatially varying material cannot be rendered in a frozen "
                                  "function (dr.freeze): Dr.Jit 1.5 would replay its texture reads from the texture "
                                  "it recorded, whatever the updates since; render it without dr.freeze")
        found: list = []
        _collect(self._owner, self._owner, found, set(), 0)
        return found


def _collect(value, owner: dict, found: list, seen: set, depth: int) -> None:
    if depth > MAX_DEPTH or id(value) in seen or isinstance(value, (JitState, str, bytes, int, float, type)):
        return
    seen.add(id(value))
    if dr.is_array_v(value):
        found.append(value)
    elif isinstance(value, mi.Object):
        if getattr(value, "__dict__", None) is not owner:  # the BSDF itself: not again
            found.append(value)
    elif isinstance(value, (list, tuple)):
        for item in value:
            _collect(item, owner, found, seen, depth + 1)
    elif isinstance(value, dict):
        for item in value.values():
            _collect(item, owner, found, seen, depth + 1)
    elif type(value).__module__.startswith("nbrdf_mitsuba") and hasattr(value, "__dict__"):
        for item in vars(value).values():
            _collect(item, owner, found, seen, depth + 1)


class FrozenOrTraced:
    """``function`` frozen (``dr.freeze``), traced as usual from the first time Dr.Jit cannot record
    it: a recording must find every live BSDF among its inputs (Mitsuba's symbolic call traces them
    all), so a scene alive beside the one rendered, such as a caller's, makes it fail. Errors of
    the function itself are raised as they are."""

    def __init__(self, function):
        self.function = function
        self._frozen = dr.freeze(function)

    @property
    def frozen(self) -> bool:
        return self._frozen is not None

    @property
    def recordings(self) -> int:
        """How many times Dr.Jit has recorded the function (0 once it is traced instead)."""
        return 0 if self._frozen is None else self._frozen.n_recordings

    def clear(self) -> None:
        """Drops the recordings now, not whenever the garbage collector frees this object: they
        refer to the scene's objects and buffers."""
        if self._frozen is not None:
            self._frozen.clear()

    def __call__(self, *args):
        if self._frozen is not None:
            try:
                return self._frozen(*args)
            except RuntimeError as error:
                if "recording a frozen function" not in str(error):
                    raise
                mi.Log(mi.LogLevel.Info, f"dr.freeze could not record {self.function.__name__} ({error}); "
                                         "traced at each call from now on")
                self._frozen = None
        return self.function(*args)
