"""How faithful is an NBRDF, against the analytic models a Mitsuba user has and against the
measured data itself, and how does its error fall with its size?

    python -m nbrdf_tools fidelity --stored-only --out docs/results/fidelity.md
    python -m nbrdf_tools fidelity [--rgl A.bsdf,B.bsdf] [--merl X.binary,...]
        [--anisotropic C.bsdf,...] [--mitsuba roughconductor_aniso,principled_aniso]
        [--mitsuba NAME=SCENE.xml|NAME=BSDF.json|NAME={"type": ...}] [--hidden 6,8,12,21,32,48,64]
        [--samples N] [--epochs N] [--out docs/results/fidelity.md] [--work out/fidelity]

For every material (RGL measurements read by Mitsuba's ``measured`` BSDF, the reference; MERL-
format tables read by the project's ``merl`` BSDF, the reference):

* **NBRDF**: ``nbrdf train`` with adaptive sampling at each width of ``--hidden`` (the size
  sweep, ``7h + h^2 + h + 3h + 3`` weights, about 100 to 5,000) and with uniform sampling at
  the paper's width 21 (675 weights), all with the same training settings; memory = the weights
  as float32 (and the size of the ``.nbrdf.json`` file);
* **analytic fits** (:mod:`nbrdf_tools.common.analytic_fit`): GGX ``roughconductor`` and
  ``roughplastic``, Blinn-Phong (7 parameters), ABC and SGD, fitted in log space to the same
  material, timed; memory = their parameters as float32;
* **references**: Mitsuba's ``measured`` (the size of its ``.bsdf`` file) and the MERL table
  (for RGL measurements tabulated with ``python -m nbrdf_mitsuba.tabulate_rgl``, reciprocal
  fold, and rendered with the ``merl`` BSDF; 33.4 MiB).

Anisotropic materials (``--mitsuba``: Mitsuba BSDFs, the built-in ones of :data:`BUILTIN` or
any scene XML / ``mi.load_dict`` JSON; ``--anisotropic``: anisotropic RGL measurements) make a
table of their own, with the BSDF itself as the reference: an anisotropic and an isotropic
NBRDF of the table's width, both distilled from it by :mod:`nbrdf_mitsuba.distill` (``--anisotropy
on`` and ``off``, the same budget), the anisotropic GGX ``roughconductor`` fit (``alpha_u``,
``alpha_v``) and the isotropic fits, all fitted on directions turned about the normal. Their
spheres are rendered with the tangent frame turned by each of :data:`FRAME_TURNS_DEG` as well, and
their log-space error's adaptive directions are turned by a random azimuth each (an adaptive pair
has ``phi_h = 0``), so the metrics see the anisotropy.

Metrics of each against the reference (:mod:`nbrdf_tools.common.metrics`; images and directions of
:mod:`nbrdf_tools.common.compare_materials`: spheres under five light elevations, means over the five):
tone-mapped MAE and RMSE, SSIM, HDR-FLIP, linear RMSE, and the log-space BRDF error
``|ln(1 + f cos) - ln(1 + f_ref cos)|`` over adaptive and uniform directions.

Outputs: the page ``--out`` (markdown, default ``docs/results/fidelity.md``) and next to it
``NAME.json`` (every number) and ``NAME.png`` (error against memory, log x); work files
(networks, tables, per-row results reused by a rerun with the same settings) in ``--work``.
With ``--stored-only`` the page is written from the stored results (``--data``, default
``docs/results/fidelity.json``) alone.
"""

from __future__ import annotations

from nbrdf_tools.pages.fidelity.command import main, parse_args
from nbrdf_tools.pages.fidelity.settings import BUILTIN, FRAME_TURNS_DEG, Material, Settings, weight_count

__all__ = ["BUILTIN", "FRAME_TURNS_DEG", "Material", "Settings", "main", "parse_args", "weight_count"]
