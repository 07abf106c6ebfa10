"""The reference of a fidelity row and the metrics of a BSDF against it: sphere images (tone-mapped
MAE and RMSE, SSIM, HDR-FLIP, linear RMSE) and the log-space BRDF error."""

from __future__ import annotations

import numpy as np

from nbrdf_tools.pages.fidelity.settings import FRAME_TURNS_DEG, Material, Settings


def load_reference(material: Material):
    """The reference BSDF: the material's file through its plugin, or the Mitsuba source."""
    from nbrdf_tools.common import compare_materials as cm

    if material.source != "mitsuba":
        return cm.load_bsdf(material.path)
    from nbrdf_mitsuba import distill

    cm.set_variant()
    try:
        bsdf, _ = distill.load_bsdf(material.path)
    except distill.DistillError as error:
        raise ValueError(str(error)) from None
    return bsdf


class Reference:
    """A material's reference BSDF and its sphere images (anisotropic materials: under each
    light and each tangent frame turn of :data:`FRAME_TURNS_DEG`)."""

    def __init__(self, material: Material, settings: Settings):
        self.bsdf = load_reference(material)
        self.anisotropic = material.group == "anisotropic"
        self.settings = settings
        self.images = self.render(self.bsdf)

    def render(self, bsdf) -> np.ndarray:
        from nbrdf_tools.common import compare_materials as cm

        turns = FRAME_TURNS_DEG if self.anisotropic else (0.0,)
        return np.concatenate([cm.render_spheres(bsdf, self.settings.resolution, frame_turn_deg=t) for t in turns])

    def measure(self, bsdf) -> dict:
        from nbrdf_tools.common import compare_materials as cm
        from nbrdf_tools.common import metrics

        images = self.render(bsdf)
        per_light = []
        for i in range(images.shape[0]):
            r = np.moveaxis(self.images[i].astype(np.float64), 0, -1)
            t = np.moveaxis(images[i].astype(np.float64), 0, -1)
            per_light.append({"mae_tonemapped": metrics.mae_tonemapped(r, t),
                              "rmse_tonemapped": metrics.rmse_tonemapped(r, t), "ssim": metrics.ssim(r, t),
                              "flip_hdr": metrics.flip_hdr(r, t), "rmse": metrics.rmse(r, t)})
        values = {k: float(np.mean([p[k] for p in per_light])) for k in per_light[0]}
        for sampling in ("adaptive", "uniform"):
            values[f"log_error_{sampling}"] = cm.log_error(self.bsdf, bsdf, sampling, self.settings.metric_samples,
                                                           turned=self.anisotropic)
        return values
