"""The sampling strategies of the convergence runs (see the package's docstring) and what each
samples the NBRDF with."""

from __future__ import annotations

STRATEGIES = ("uniform", "cosine", "phong-fit", "two-lobe-fit", "phong-predicted", "tabulated", "default", "measured")

# None: the BSDF without a ``sampling`` parameter, i.e. the file's ``sampling.default``.
NBRDF_SAMPLING = {"uniform": "uniform", "cosine": "cosine", "phong-fit": "phong", "two-lobe-fit": "two_lobe",
                  "phong-predicted": "phong", "tabulated": "tabulated", "default": None}

#: What ``--strategies`` renders unless told: ``default`` is one of the others under another
#: name (the one the file names), so it is rendered only on request.
DEFAULT_STRATEGIES = tuple(s for s in STRATEGIES if s != "default")

#: The plates' BSDF of the cost floor (timed beside ``measured``): one that costs next to nothing,
#: so its render time is the scene's share of every render.
COST_FLOOR_BSDF = "diffuse"


def kitchen_skip_reason(strategy: str, has_phong: bool, has_two_lobes: bool) -> str | None:
    """Why a strategy is not rendered in the kitchen, None when it is: every replaced material
    needs what the strategy samples with, and the kitchen's materials are MERL tables."""
    if strategy == "measured":
        return "Mitsuba's measured BSDF needs RGL measurements, the kitchen's materials are MERL tables"
    if strategy == "phong-predicted":
        return "the predicted lobe is measured in the Veach scene only"
    if strategy == "phong-fit" and not has_phong:
        return "not every replaced material has a fitted lobe (nbrdf fit-phong)"
    if strategy == "two-lobe-fit" and not has_two_lobes:
        return "not every replaced material has a two-lobe mixture (nbrdf fit-phong --lobes 2)"
    return None
