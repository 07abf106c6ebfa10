"""The prose of docs/results/scenes.md; its tables are stored in docs/results/data/scenes.json."""

# ruff: noqa: E501  (TEMPLATE holds the page's lines as they are)
from __future__ import annotations

from nbrdf_tools.common import stored_page

PAGE = "scenes"

# Each {{table NAME}} line is the stored table NAME.
TEMPLATE = r'''# Results: sampling in scenes

```sh
python -m nbrdf_tools scenes --stored-only --out docs/results/scenes.md   # this page, from its stored data
python -m nbrdf_tools scenes --scene veach                    # 9 MERL + 2 RGL materials, pure BSDF sampling
python -m nbrdf_tools scenes --scene veach --integrator mis   # the same with MIS
python -m nbrdf_tools scenes --scene kitchen [--kitchen PATH] # path tracing, 14 materials replaced
python -m nbrdf_tools scenes --scene veach --quick --json out.json   # tiny run (CI)
```

A quick-setting example of the plots (one material, 5 seeds, a few minutes):

```sh
python -m nbrdf_tools scenes --scene veach --materials aluminium --rgl "" --width 192 \
    --max-spp 64 --gt-spp 512 --seeds 5 --train-args "--epochs 20 --samples 200000" \
    --out out/convergence-example
```

![RMSE against spp and render time for aluminium in the Veach scene: uniform, cosine and Phong sampling, median of 5 seeds with min-max bands](../images/convergence-example.png)

This is `out/convergence-example/veach/plots/veach-aluminium.png` (a PDF lies beside it) of a
run with these quick settings on a shared 2-core machine (104 s with other jobs running; briefly
trained network, 192x128, references at 512 spp), so its times are inflated and its curves
noisier than the full runs' below. Pure BSDF sampling (the default `--integrator bsdf`): the
Phong lobe follows the 1/sqrt(spp) guide, while cosine and uniform sampling rarely hit the small
lights in the sharp reflections and stay flat, with a wide spread between seeds. The dashed line
is the representation error (the converged NBRDF against the table's ground truth).

The scenes are described in [mitsuba.md](../mitsuba.md#scenes) and
[design.md section 10](../design.md#10-scenes).

## Method

For each material, the script renders each sampling strategy at 1, 2, 4, ... spp. The strategies
are `uniform`, `cosine`, `phong-fit` (our NBRDF sampled through the best single Blinn-Phong lobe,
`nbrdf fit-phong --lobes 1`), `two-lobe-fit` (the two-lobe mixture of `nbrdf fit-phong --lobes 2`,
stored in the network file), `phong-predicted` (the lobe that `nbrdf predict-phong` gives from the
autoencoder's code and the network's highlight profile, with `--ae AE.json --predictor P.json`; skipped with a note otherwise)
and `measured` (Mitsuba's own sampling of an RGL measurement). Every render is timed by wall
clock after its kernels are compiled; renders of up to 32 spp are repeated and the fastest
time kept. Each render is then compared with a converged render of the same BSDF, which isolates
the sampling error. In the Veach scene the metrics are measured on the plates only; in the
kitchen, on the whole image.

**Metrics** (names of `nbrdf_tools.common.metrics`, as in the JSON and CSV; linear RGB):

* every strategy render: `mae`, `rmse`, `relmse` (ε = 0.01), `mape` (ε = 0.01) and `psnr_peak1`
  (PSNR with peak 1) against the converged render of the same BSDF (the sampling error), and the
  same five against the ground truth as `*_vs_ground_truth`; `seconds`; `nonfinite` pixels;
* the representation rows (converged NBRDF vs ground truth): those five, `relative_rmse`, and over
  the whole image `ssim` (scikit-image, Wang et al.'s settings, on tone-mapped images) and
  `flip_hdr` (NVIDIA's HDR-FLIP, `flip-evaluator`);
* the kitchen: non-finite and firefly counts of the NBRDF and table renders.

The plots show `rmse`; with `--seeds N` each point is the median of N independent renders and
the band their minimum and maximum. The equal-time figures (`equal_time` in the JSON) are the
median over seeds (`rmse`) and the root mean square over seeds (`rmse_pooled`), and for RGL
materials each strategy's RMSE over `measured`'s (`vs_measured`, `best_nbrdf`,
`best_vs_measured`; the table in [sampling.md](sampling.md)), and with `phong-fit` each strategy's
RMSE over the single lobe's (`vs_phong_fit`). Beside `measured`, the Veach plates are also
rendered in `diffuse` and only timed (`timings`): a BSDF that costs next to nothing, so its time
is the scene's share of every render; `cost_floor` gives at the highest common spp each
strategy's RMSE and time over `measured`'s and the equal-time ratio its per-sample error would
reach if its BSDF cost nothing (per-sample ratio x sqrt(`diffuse` time / `measured` time)). `--strategies` picks a subset, in both scenes; the
kitchen samples all its replaced materials with the same strategy and skips `measured` and
`phong-predicted` with a note.

Outputs go to the output folder (`--out`, default `out/convergence/SCENE/`): `convergence.csv`, `convergence.json`
(`{"results": [{"scene", "material", "strategy", "spp", "seed", "seconds", "mae", "rmse", "relmse", "mape", "psnr_peak1", ...}],
"representation": [...], "equal_time": [...], "timings": [...]}`), EXR renders, log-log plots of error against
spp and against seconds (`plots/`, PNG and PDF), and `summary.md`. `--replot` redraws the plots
from the JSON.

Artefacts are cached (paths below are the defaults under `out/`):

* `out/materials/`: tables from `nbrdf synth` or `python -m nbrdf_mitsuba.tabulate_rgl`, networks
  from `nbrdf train` (on the MERL table, or on the RGL measurement itself), the two-lobe mixture
  stored in those network files and the best single lobe. Each comes with an `*.artefacts.json`
  file recording its inputs (and the single lobe).
* `out/references/`: ground truths and converged references, each an EXR with a JSON sidecar.
  The cache key covers the scene description, the hashes of the input files, spp, resolution,
  integrator and the code version. A reference is re-rendered when any of these changes.

The ground truth is the table through the `merl` BSDF, or for RGL materials the measurement
through Mitsuba's `measured` BSDF. It is rendered with MIS, which converges to the same image as
pure BSDF sampling but with far less noise. The converged NBRDF is rendered with the same random
numbers as the ground truth, so the **representation error** (NBRDF against ground truth) is not
buried in noise.

CI runs the script (and `bench_rays`, [performance.md](performance.md)) with `--quick --json`
and checks the shape of their JSON output (`tests/test_scenes.py`).

## Results (2-core CPU, `llvm_ad_rgb`; NBRDFs trained with `nbrdf train`, default recipe)

Other jobs shared the machine (training runs), so absolute times are inflated; the strategies'
renders were interleaved, so the load hit them alike and the ratios hold. The Phong lobes are
those `nbrdf fit-phong` stores by default: the lowest-variance lobe (`nbrdf-core/src/lobe_fit.rs`).

### Veach scene, pure BSDF sampling

384x256, 1–64 spp, references at 512 spp. RMSE on the plates
at equal render time (the longest time every strategy reached, read off each strategy's
log-log curve):

{{table table1}}

### Veach scene, MIS

The same comparison with MIS (`--integrator mis`; 4 MERL materials and 1 RGL material). Emitter
sampling already handles the small lights, so the choice of BSDF sampling matters much less:

{{table table2}}

### Representation error

NBRDF against ground truth, 512 spp, plates, same random numbers:

{{table table3}}

Relative RMSE is the RMSE divided by the RMS of the ground truth on the plates. For the RGL
materials the ground truth is the measurement itself (Mitsuba's `measured` BSDF), so the `table`
row is the error of tabulating it onto the MERL grid (the NBRDF learns that table).

### Kitchen

Path tracing (max depth 8), 320x180, 1–128 spp, references at 1024 spp:

{{table table4}}

{{table table5}}

Kitchen checks: no non-finite value in any strategy render, in the converged NBRDF, or in the
Phong-sampled 128 spp renders of the NBRDF and of the table made with the same random numbers;
no firefly there (luminance above 10 × ground truth + 1) in either, out of 57,600 pixels. (With the
model-fit lobes of our first run, 7 pixels on the gray-plastic worktop were outliers, sampled
through its near-cosine `n = 7·10^4, w = 0.005` lobe.) The replaced materials cover 49 % of the
image.

Plots: `out/convergence/veach/plots/veach-overview.png` (all materials) and
`out/convergence/veach/plots/veach-NAME.png` (error against spp and against time for each
material); the MIS run's are `veach-mis-overview.png` and `veach-mis-NAME.png`; the kitchen's is
`out/convergence/kitchen/plots/kitchen.png`. Renders: `out/convergence/veach/renders/NAME/` and
`out/convergence/kitchen/renders/kitchen/`.

### What the figures show

* **Choosing the lobe for sampling, not for shape.** The 7-parameter fit of [design.md section 6](../design.md#6-blinn-phong-importance-sampling)
  matches the BRDF in log space; on materials with a weak, very sharp spike over a diffuse base it
  returns lobes like `n = 7·10^4, w = 0.005` (gray-plastic) that put almost no samples where the
  reflected energy is, and such lobes sampled no better than cosine (phong / cosine 0.80–1.28 on
  6 of 11 materials in our first run). `fit-phong` now searches `(n, w)` for the lowest relative
  variance of BSDF sampling, `∫ g²/p / (∫ g)²` with `g = f cos θ_l`, by quadrature over the half
  vector averaged over view angles (`--lobe model` keeps the model fit's lobe). With it
  color-changing-paint3 went from 1.15 to 0.12 of cosine, gray-plastic from 1.28 to 0.51, the RGL
  paints from 0.80–0.88 to 0.29–0.36, and no material got worse.
* **Where Phong sampling halves the error, and where it cannot.** At equal time, Phong sampling
  reaches at most half the RMSE of cosine sampling on the glossy plates: aluminium 0.09, nickel
  0.12, color-changing-paint3 0.12, cc_ibiza_sunset 0.29, cc_iris_purple_gem 0.36 (and 0.04–0.27
  of uniform), with gray-plastic (0.51) and blue-metallic-paint (0.54) at the threshold. On
  black-oxidized-steel (0.88), green-metallic-paint (0.73) and red-specular-plastic (0.80) most of
  the plates' noise comes from the diffuse part of the BRDF hitting the small, bright lights,
  which no BSDF lobe can aim at: the variance search is the optimum over all Blinn-Phong lobes for
  randomly placed lights, and hand-picked lobes (n = 100–2000, w = 0.3–0.6) tried on these did
  no better than 0.8. Emitter sampling (MIS) is the remedy there. pink-fabric (diffuse control)
  stays at cosine sampling (0.99).
* **Measured sampling.** On the RGL materials the Blinn-Phong lobe on our NBRDF now comes within
  6–10 % of Mitsuba's own sampling of the measurement (0.62 vs 0.58 and 0.59 vs 0.54 RMSE). A
  later run on all four RGL materials, with networks trained on the measurements themselves, the
  two-lobe mixture and the median of 6 seeds, is level with or ahead of `measured` at equal time
  (best strategy 0.78–0.97x its RMSE), by speed rather than by the sampler:
  [sampling.md](sampling.md#veach-scene-rgl-measurements-against-mitsubas-measured).
* **Representation error.** The NBRDFs of the MERL materials are within 3.5 % relative RMSE of
  their tables on the plates (PSNR 33–66 dB). For the RGL materials the NBRDFs are within 8.4 %
  of the measurement, of which 6.2–7.2 % is already lost when tabulating onto the MERL grid.
* **Heavy-tailed noise.** With pure BSDF sampling, the Veach scene's smallest, brightest lights
  make the per-render RMSE heavy-tailed; single-render points can jump, and cosine and uniform
  stay flat on the sharpest materials up to 64 spp. The equal-time figures come from single
  renders.

Lobes and sampling choices that were tried and not kept: [experiments.md](../experiments.md#sampling).

### Kitchen: two lobes, the table and the stored default

```sh
python -m nbrdf_tools scenes --scene kitchen --strategies cosine,phong-fit,two-lobe-fit,tabulated,default \
    --width 160 --max-spp 128 --gt-spp 512 --seeds 3 --train-args "--epochs 10 --samples 100000" \
    --out out/kitchen-strategies
```

The strategies of [sampling.md](sampling.md#merl-materials-in-the-veach-scene-against-one-lobe-and-the-stored-default)
in the kitchen: all 14 replaced BSDFs (13 MERL materials) sampled with the same strategy, path
tracing (max depth 8), 160x90, 1-128 spp, 3 seeds, references at 512 spp, errors on the whole
image. Networks: `nbrdf train` with a short budget (10 epochs, 100k samples), then `nbrdf
fit-phong --lobes 1` and `--lobes 2`, which stored `tabulated` as the default of 11 materials
(with the table's cosine weight 0.02 on 7, 0.05 on fruitwood-241, 0.1 on the fabrics,
polyethylene and yellow-paint), `two_lobe` of aluminium and `cosine` of
specular-orange-phenolic. 6 minutes on the quiet 2-core machine with networks cached (run of
2026-11-24, with the kernels that leave out units that never fire and the table stored for one
side of the plane of incidence). RMSE at equal time (2.7 s, cosine's 128 spp render), median of
3 seeds, and its ratio to `phong-fit`'s:

{{table table6}}

(Earlier runs: before the pruning and the halved table, 3.0 s: 1.18, 0.99, 1.04, 1.04; with the
binary-search table under load, 5.4 s: 1.07, 0.95, 1.04, 1.03.)

* **In the kitchen the choice among the lobes and the table hardly matters.** At equal spp (128)
  the median RMSE is 0.0702 (`phong-fit`), 0.0679 (`two-lobe-fit`, 0.97), 0.0695 (`tabulated`,
  0.99) and 0.0703 (`default`, 1.00), differences of the size of the spread between seeds (min-max
  about ±3-4 %); only cosine is clearly behind (0.0809, 1.15). Half the image is untouched
  materials, and the errors are over the whole image with path tracing, so much of the noise
  comes from paths that the replaced materials' sampling does not steer; the plates of the Veach
  scene isolate the BSDF sampling much better.
* **At equal time the table loses a little to one lobe** (1.04): the `tabulated` and `default`
  renders took 6-9 % longer at 128 spp (3.02 and 2.94 s against 2.78 s for `phong-fit`; every
  strategy's renders are 8-11 % faster than in the previous run, from the pruned kernels), which
  eats their small lead at equal spp. Path tracing evaluates the table's pdf at every vertex (MIS
  with the emitter samples) and gathers from 14 tables, so the cheaper table gained less here
  than in the Veach scene (5-10 % slower before). With 3 seeds that difference is within the
  noise of the timings.
* **Timing caveat.** At 160x90 a render has a fixed cost of about 1 s, so up to 32 spp the times
  are flat and the curves carry no equal-time information; the equal-time point is at 128 spp,
  where the samples dominate.
* No non-finite value in any render, and no firefly in the Phong-sampled 128 spp renders of
  the NBRDF and the table (14,400 pixels); representation error of these briefly trained networks:
  RMSE 0.036 on the image (relative 1.4 %).
'''


def page(data: dict) -> str:
    return stored_page.fill(TEMPLATE, data)


def write_stored(out, data_file=None) -> None:
    """The page from its stored data (``--stored-only``)."""
    data_file = data_file or stored_page.data_path(PAGE)
    stored_page.write(out or stored_page.page_path(PAGE), page(stored_page.load(data_file)))
    print(f"wrote {out or stored_page.page_path(PAGE)} from {data_file}")
