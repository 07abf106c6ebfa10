"""What a fidelity run measures: its constants, the settings that key its cached rows, the
materials."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


PAPER_HIDDEN = 21

DEFAULT_HIDDEN = (6, 8, 12, 21, 32, 48, 64)

DEFAULT_MODELS = ("roughconductor", "roughplastic", "blinn_phong", "abc", "sgd")

MERL_TABLE_BYTES = 12 + 3 * 90 * 90 * 180 * 8

METRICS = ("mae_tonemapped", "rmse_tonemapped", "ssim", "flip_hdr", "rmse", "log_error_adaptive",
           "log_error_uniform")

# Lower is better for all but SSIM.
HIGHER_IS_BETTER = {"ssim"}

METRICS_VERSION = 1

# Stored fits made by other fitting code are redone.
FITS_VERSION = 2

# Anisotropic materials: the tangent frame turns of their sphere images (degrees).
FRAME_TURNS_DEG = (0.0, 45.0, 90.0)

# The built-in anisotropic Mitsuba BSDFs of --mitsuba (alpha_u along the tangent).
BUILTIN = {
    "roughconductor_aniso": {"type": "roughconductor", "distribution": "ggx", "material": "Au",
                             "alpha_u": 0.05, "alpha_v": 0.3},
    "principled_aniso": {"type": "principled", "base_color": {"type": "rgb", "value": [0.75, 0.4, 0.2]},
                         "metallic": 0.7, "roughness": 0.35, "anisotropic": 0.8, "specular": 0.5},
}

# Analytic models of the anisotropic table (before --models' isotropic ones).
ANISOTROPIC_MODELS = ("roughconductor_aniso",)


def weight_count(hidden: int) -> int:
    """Weights and biases of the 6-h-h-3 network."""
    return 6 * hidden + hidden + hidden * hidden + hidden + 3 * hidden + 3


@dataclass
class Settings:
    hidden: tuple[int, ...]
    uniform_hidden: tuple[int, ...]
    samples: int | None
    epochs: int | None
    seed: int
    models: tuple[str, ...]
    fit_samples: int
    resolution: int
    metric_samples: int
    tabulate: bool
    table_hidden: int = PAPER_HIDDEN  # the width of the representation table

    def training_key(self) -> dict:
        return {"samples": self.samples, "epochs": self.epochs, "seed": self.seed}

    def metric_key(self) -> dict:
        return {"resolution": self.resolution, "metric_samples": self.metric_samples, "metrics": METRICS_VERSION}


@dataclass
class Material:
    name: str
    path: Path
    source: str  # "rgl", "merl" or "mitsuba"
    group: str  # "isotropic" or "anisotropic"
    spec: str = ""  # what the user named (--mitsuba)
    plugin: str = ""  # the Mitsuba plugin of a --mitsuba source, when known
