"""Convergence of the sampling strategies: error against samples per pixel and against render time.

For each material, the scene is rendered with every sampling strategy at 1, 2, 4, ... spp and
each render is timed (wall clock, after the kernels are compiled; renders of up to 32 spp are
repeated with the same seed and the fastest time kept) and compared with a converged
reference; a CSV, a JSON file, EXR renders, PNG plots (log-log, one curve per strategy) and a
Markdown summary land in the output folder.

Strategies (docs/design.md section 6): ``uniform``, ``cosine``, ``phong-fit`` and ``two-lobe-fit``
sample our NBRDF (the ``nbrdf`` BSDF, sampling ``uniform``, ``cosine``, ``phong``, ``two_lobe``) by
the uniform hemisphere, the cosine lobe, the best single Blinn-Phong lobe (``nbrdf fit-phong
--lobes 1``) and the two-lobe mixture (``--lobes 2``, stored in the network file);
``phong-predicted`` samples the NBRDF through the lobe that the latent-space predictor gives
(``--ae AE.json --predictor P.json``, from ``nbrdf ae train`` and ``nbrdf predictor train``;
skipped with a note without them); ``tabulated`` samples the NBRDF's half-vector table (built
when the plugin loads it); ``default`` (only when named in ``--strategies``) loads the NBRDF with no
``sampling`` at all, i.e. with the strategy that ``nbrdf fit-phong`` stored as the file's
``sampling.default`` (named in the JSON's ``default_sampling``); ``measured`` is Mitsuba's own ``measured`` BSDF with its own
sampling (RGL materials only; it samples the measurement with its data-driven warp).

Several seeds (``--seeds``) handle the heavy-tailed noise of single renders: the equal-time
figures (``equal_time`` in the JSON, the summary's tables) are the median over seeds of the RMSE
(``rmse``), beside the root of the mean squared error over seeds (``rmse_pooled``); for RGL
materials also each strategy's RMSE over ``measured``'s at the same time (``vs_measured``) and
the best NBRDF strategy (``best_nbrdf``, ``best_vs_measured``).

Beside ``measured``, the Veach scene is also rendered, timed only, with ``diffuse`` plates (a
BSDF that costs next to nothing; ``timings`` in the JSON): its render time is the scene's share
of every render, so it bounds what any BSDF can gain on ``measured`` at equal time. The summary
(``cost_floor``) gives, at the highest common spp, each strategy's RMSE and time over
measured's and that bound (per-sample ratio x sqrt(floor time / measured's time)).

References and ground truths (cached under ``OUT/references`` with JSON sidecars, re-rendered when
any input changes; see ground_truth.py), all with multiple importance sampling (emitter + BSDF
samples: the same integral, much less noise) at ``--gt-spp``:

* the ground truth: the tabulated material through the ``merl`` BSDF (MERL materials), or the
  measurement through Mitsuba's ``measured`` BSDF (RGL materials);
* the converged NBRDF: our network at the same sample count, with the same random numbers.

The sampling error of a strategy is measured against the converged render of the *same* BSDF
(fields ``mae``, ``rmse``, ``relmse``, ``mape``, ``psnr_peak1``; see nbrdf_tools.common.metrics): the
NBRDF for ``uniform``/``cosine``/``phong-*``, the measurement for ``measured``. The
representation error (NBRDF against ground truth at ``--gt-spp``) is reported separately, with
the same metrics plus ``ssim`` (scikit-image) and ``flip_hdr`` (NVIDIA's HDR-FLIP) over the whole
image, and the total error of every render against the ground truth is in the
``*_vs_ground_truth`` fields.

In the Veach scene the errors are measured on the plates only (the floor and wall are diffuse);
in the kitchen on the whole image. The kitchen replaces several materials at once, and a strategy
there samples every replaced material alike (skipped with a note when one of them lacks what it
samples with); ``measured`` (RGL only) and ``phong-predicted`` are skipped there with a note. Its
summary gives the stored defaults as counts over the materials (``default_sampling``, per
material in ``default_samplings``).

    python -m nbrdf_tools scenes --scene veach [--materials a,b] [--rgl x,PATH.bsdf] [--integrator bsdf|mis]
        [--strategies a,b] [--seeds N]
    python -m nbrdf_tools scenes --scene kitchen [--kitchen PATH] [--strategies a,b] [--seeds N]
    python -m nbrdf_tools scenes --scene veach --quick --json out/convergence.json

MERL materials need nothing but the CLI (tables are synthesised from the embedded fits and the
networks trained); RGL materials need their ``.bsdf`` measurement (a path, or a name in the shared
data; the default RGL pair is left out with a note when the shared data is absent), the kitchen
its scene. What is missing is reported before any work starts. Everything, caches included,
goes under ``--out`` when it is given.
"""

from __future__ import annotations

from nbrdf_tools.pages.scenes.command import main, parser
from nbrdf_tools.pages.scenes.metrics import cost_floor, equal_time_summary, rmse_at_time, series

__all__ = ["cost_floor", "equal_time_summary", "main", "parser", "rmse_at_time", "series"]
