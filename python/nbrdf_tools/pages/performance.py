"""The performance page, docs/results/performance.md, from the benchmark results stored in
docs/results/data/performance.json (the tables of ``python -m nbrdf_tools bench-rays --json``,
``python -m nbrdf_tools bench-many --json`` and the criterion figures of ``make bench``, each
table's source named in the file's ``sources``). It measures nothing: the benchmarks the page
names are the way to measure anew, and their figures go into the data file's tables.

    python -m nbrdf_tools performance --stored-only --out docs/results/performance.md
"""

# ruff: noqa: E501  (TEMPLATE holds the page's lines as they are)
from __future__ import annotations

import argparse
import sys

from nbrdf_tools.common import stored_page

PAGE = "performance"

# The page's prose; each {{table NAME}} is the stored table NAME.
TEMPLATE = r'''# Results: performance

```sh
python -m nbrdf_tools performance --stored-only --out docs/results/performance.md   # this page, from its stored data
make bench                                   # criterion: evaluations, lookups, samples, training
python -m nbrdf_tools bench-rays --json out/bench/rays.json   # the speed table below (4.7 min)
python -m nbrdf_tools bench-rays [--json FILE] [--modes default,wavefront] [--rgl PATH.bsdf]
python -m nbrdf_tools bench-rays --variant scalar_rgb [--bsdfs nbrdf]   # the rust backend, one direction per call
python -m nbrdf_tools bench-many --json out/bench-many/bench.json          # "Many materials" (commands there)
```

`bench_rays` puts each BSDF under test on the four plates of the Veach scene (direct illumination
with MIS: per sample one camera ray, one shadow ray and one BSDF ray), renders once to compile,
then times several renders; runs of the different BSDFs alternate within one process so that
machine load affects them alike. Modes: `default` (Dr.Jit's symbolic loops and calls, Mitsuba's
megakernel) and `wavefront` (symbolic loops and calls off, which the `rust` backend needs).
`--quick` is the small CI run. In a scalar variant (`--variant scalar_rgb`) there is one mode,
`scalar`, with the `rust` backend only; `--bsdfs` times a subset (`roughconductor`, the reference
of the ratios, is always added); docs/mitsuba.md's table compares the two variants.

**What each report carries.** `make bench` (criterion): evaluations, lookups, samples and
training samples per second. `bench_rays`: per BSDF and mode, `mrays_per_s` (camera, shadow and
BSDF rays per second, from the median render time), `seconds`, `memory_bytes` (the bytes of the
material's data: a network's float32 parameters, with `file_bytes` its JSON file; the MERL table
and the RGL file as stored; a built-in's parameters that `mi.traverse` exposes, as float32) and
the ratios `ratio_vs_measured` and `ratio_vs_roughconductor`, printed, in its JSON (`--json`,
`bsdfs.NAME.*`; with both modes under `runs`) and as a bar chart labelled with the memory (PNG and
PDF, `--plot`, default `OUT/rays_per_second.png`). Neither computes image metrics: the renders' errors (`mae`, `rmse`,
`relmse`, `psnr_peak1`, `ssim`, `flip_hdr`) are those of [scenes.md](scenes.md) and
[training.md](training.md).

## The speed table: representations and sampling strategies

`python -m nbrdf_tools bench-rays --json out/bench/rays.json` (defaults: 768x512, 16 spp, 5
rounds, both modes; 4.7 minutes): the Veach scene with MIS (3 rays per sample), `llvm_ad_rgb`,
runs alternated in one process. The network is the authors' gold-metallic-paint (675 weights,
width 21) after `nbrdf fit-phong --lobes 2`, which stores two lobes and, by the lowest variance,
`sampling.default = tabulated` (cosine weight 0.02): so `nbrdf` samples with the half-vector
table, built when the material loads (the "+ table" bytes: its float32 masses and alias
tables in the traced twin, not in the file); `nbrdf-phong` samples the first lobe. `measured`
is Mitsuba's BSDF of the shared `paper_white_rgb.bsdf`, `merl` the SGD table of
gold-metallic-paint. Run of 2026-11-24 (units that never fire left out, the table stored for one
side of the plane of incidence), quiet machine (load average 1.5-2):

{{table speed}}

Against the issue's targets in Mitsuba's default mode (>= 1.0x `measured`, >= 0.9x
`roughconductor`): **`nbrdf` with its stored default is at 1.34x `measured` and 0.93x
`roughconductor`**, every strategy is above both (1.30-1.38x, 0.90-0.96x), and only the opaque
weights (a scene-parameter variant for optimisation) are below (0.94x, 0.65x). In the wavefront
mode every `nbrdf` strategy is level with `roughconductor` (0.92-0.99x). The run just before
the table was halved (same day, same code otherwise): `nbrdf` 1.34x / 0.92x, the strategies
1.34-1.40x / 0.92-0.97x; the differences between strategies (1-4 %) are within the run-to-run
noise.

![Rays per second and memory of nbrdf (each sampling strategy), merl, measured and Mitsuba's built-in BSDFs in the Veach scene, default and wavefront modes](../images/rays-per-second.png)

This is `out/bench/rays_per_second.png` (a PDF lies beside it) of the run above.

## Library throughput

Measured on the 2-core CI-sized machine (AMD EPYC, AVX2+FMA) with `make bench` (criterion) and
`bench_rays`; other jobs shared the machine during most runs, so the quiet
figures are best-of runs and the loaded ones are lower bounds.

{{table throughput}}

Kernel variants that were measured and not kept: [experiments.md](../experiments.md#speed).

## Many materials

```sh
python -m nbrdf_tools bench-many --counts 1,16,64 --rounds 2 --json out/bench-many/bench-64.json
python -m nbrdf_tools bench-many --counts 256 --modes auto,opaque,roughconductor --rounds 2 --json out/bench-many/bench-256.json
python -m nbrdf_tools bench-many --json out/bench-many/bench.json     # one round of everything, literal at 256 included (15 min)
python -m nbrdf_tools bench-many --quick                               # CI size
```

N unit spheres in a grid, each with its own network (the authors' MERL networks, imported;
beyond their 100, copies with tinted output biases, so that every sphere has distinct weights),
a constant environment and a directional light, `path` (`max_depth` 3), 256x256, 16 spp,
`llvm_ad_rgb`, the files' default sampling (`cosine`: the imported networks store no lobe).
Each (count, mode) runs in its own process with an empty Dr.Jit kernel cache, so the first render
compiles from scratch and no other scene's BSDFs enter Mitsuba's symbolic call; the modes
alternate, and each figure is the median over the rounds. Wall seconds with the process's CPU
seconds (all threads) in parentheses; `first / one`: the first render's CPU time over one
network's in the same mode (the issue's ratio); `compile`: LLVM's compile time within the first
render (wall seconds, from Dr.Jit's kernel history: under load mostly waiting for a core);
`later` is the median of three renders after the first; `vs best`: later-render CPU time over
the fastest `nbrdf` mode's at that count; `codegen`: Dr.Jit's code generation per later render
(Mitsuba retraces the scene every render; Dr.Jit regenerates the IR, assembles every instance's
call data and finds the kernel in its cache); `RSS`: the growth of the resident memory while the
scene loads, per material.

**Run of 2026-11-27 on a quiet machine** (the two commands above, one after the other; load
average 1.4-1.9 during the first, which is the benchmark's own threads, 0.2-0.9 during the
second; nothing else running). The 256 rows' `first / one` is over the first command's
one-network row of the same mode, and `later vs best` at 256 is over the faster of `auto` and
`opaque` (`literal` is not run there):

{{table many_quiet}}

A loaded run below gave the same picture with CPU times up to 2x higher; the quiet figures are
the ones the targets are judged on.

Run of 2026-11-26 on the shared 2-core machine with four other agents working: load average
15-21 (the wall times are 2-3x the CPU times; the CPU times are the figures to compare, and even
they vary by up to 30 % between rounds: `auto` and `opaque`, which trace the same shared kernel,
gave 1.41 and 1.07 against 0.91 and 0.92 CPU s per later render at 64 networks, and 0.79-1.07
against 0.77-0.95 when rerun interleaved a minute later).

{{table many_loaded}}

(The 256 rows are from the second command, run right after the first; their `first / one` is
over the first command's one-network row. `literal` at 256 is left out of the two-round runs: one
round of it on 2026-11-25, under a load of 10-13: first render 426 s wall (82 CPU s, nearly all
of it compiling 256 kernels), later renders 2.6 CPU s.)

What the figures say, against the targets of issue 31 (64 distinct networks):

* **Loading: met.** 2.3-3.0 CPU ms per network with `auto` and `opaque` at 64 on the quiet
  machine, 3.6-4.1 in the loaded run (wall 7 ms under that load), against 45-53 ms with `literal` weights, whose load proves the dead units.
* **First render: grows slowly, but not within 2x of one network's, and out of the plugin's
  reach.** On the quiet machine `auto` at 64 networks takes 2.28 CPU s, 3.3x one network's 0.68 s
  (`opaque`: 1.79 s, 2.6x that one-network render, 1.1x its own), at 256 3.75 s, against 13 s at 64 with
  literal weights; in the loaded run 2.0-2.9 CPU s (4.2x one network's 0.58 s), at 256 3.6-5.2 s,
  against 18 s at 64 with literal weights. Where it goes (docs/experiments.md, "Where the shared
  kernel's time goes", with the IR): LLVM compiles the shared kernel in about 0.85 CPU s (one
  literal network's kernel: 0.31-0.36 s); half of that is the call data (below), the rest the
  network's arithmetic with no unit left out. Retracing 64 instances and generating their code
  takes about 0.6 s more, and rendering 64 spheres about 0.3 s: even with the kernel already
  compiled (a warm cache) the first render at 64 networks is 0.91 CPU s, 1.4-1.9x one network's
  first render *including* its compile. Meeting 2x would leave the shared kernel no more than
  about 0.3 s of compilation, less than one literal network costs.
* **Later renders: not within 1.1x of the fastest mode at 16 and 64 networks** (1.4-1.7x of
  `literal` on the quiet machine, 1.5-2.0x in the loaded run, 1.3-1.7x in the run of 2026-11-25); at 256 `auto` and `opaque` are the
  fastest that render at all. Two costs scale with the shared kernel, both inside Dr.Jit 1.5:
  each of the 654 weights is call data that the LLVM backend loads per lane packet at the
  instance offset of each of the 8 lanes, through an 8x8 transpose (8 loads, 24 shuffles per 8
  weights), as many instructions as the network's own multiply-adds; and every render Dr.Jit
  assembles the call data of N x 675 variables again (`codegen`: 0.18-0.22 s per render at 64
  networks against 0.08 s with literal kernels, 0.73-1.03 s at 256). Literal kernels fold the
  weights into the code and leave out the dead units (30 % of the multiply-adds of the
  authors' networks). What was tried to close the gap and did not pay (units dead in every
  network, one network evaluation per `eval_pdf_sample`, Dr.Jit's cooperative vectors, a
  vectorised trace) is in [experiments.md](../experiments.md#speed).
* **256 networks load and render on the 2-core machine**: on the quiet machine 0.56-0.90 CPU s to
  load, 3.3-3.8 for the first render, 2.3-2.6 per later render (loaded run: 0.9, 3.6-5.2, 2-3); RSS 0.36 MB per network (2.7 kB of it the float32 weights; a
  tabulated sampler adds a 147 kB table), `roughconductor` 0.05 MB.
* **CUDA** (one H100, below): each GPU thread loads its own call data, with no transposes, and
  the targets nearly hold there: at 64 networks `auto`'s first render is 1.55x one network's
  (target 2x), its later renders 1.14x `literal`'s (target 1.1x), loading 12 ms per network.

## CUDA: one NVIDIA H100 (2026-11-27)

```sh
make test-cuda                                    # the plugin's tests in cuda_ad_* (NBRDF_TEST_JIT=cuda)
python -m nbrdf_tools bench-rays --variant cuda_ad_rgb --spp 64 --json out/bench/rays-cuda.json \
    --plot docs/images/rays-per-second-cuda.png
python -m nbrdf_tools bench-many --variant cuda_ad_rgb --counts 1,16,64 --modes auto,opaque,literal,roughconductor \
    --json out/bench-many/cuda-64.json
python -m nbrdf_tools bench-many --variant cuda_ad_rgb --counts 256 --modes auto,opaque,roughconductor \
    --json out/bench-many/cuda-256.json
```

The only GPU run so far: one lent machine (NVIDIA H100 80GB HBM3, driver 580.159.04, CUDA 13.0,
16 CPU cores), Mitsuba 3.9.1 and Dr.Jit 1.5.0 from their Python 3.12 wheels, the library built
here; one round of each benchmark (the machine was lent for 15 minutes in all).

**Tests.** The plugin's test files that `make test-cuda` names ran with every `llvm_ad_*`
variant mapped to its `cuda_ad_*` twin (`cuda_ad_rgb`, `cuda_ad_mono`, `cuda_ad_mono_polarized`,
`cuda_ad_spectral`, `cuda_ad_spectral_polarized`): the backend parity tests, every chi2 test
(Phong, two lobes, tabulated, anisotropic, the zoomed n = 1e4 and 1e6 lobes, the spectral
variant's), the variants' values and renders (mono equals the luminance of RGB, the spectral
Veach render follows the RGB one), the many-materials and estimation tests. 345 passed on the
first run and 2 failed: the zoomed chi2 of the traced Phong pdf at n = 1e6 (both view angles).
Its `ln(1 - x)` used Kahan's `log(1 - x) x / ((1 - x) - 1)`; it is now a series below x = 1/16
(`jit._log1m`, with a float64 test that passed there too), and on the second run both passed,
with the rest of those files. Why the Kahan form failed on the GPU was not isolated in the time
lent (CUDA's `log` at 1 - 1e-6 was accurate in a spot check). Not seen passing on the GPU:
`test_network_recovery_with_the_prior` failed there only because the `nbrdf` command was not on
that machine's `PATH` (the estimate then writes no fitted sampling, and says so; the test asks for
it), and the two tests of the prior's held-out choice did not finish within the time left. A
one-step nbrdf estimate took 64 s in `cuda_ad_rgb` on the fresh machine's empty kernel cache. The
same estimate in `llvm_ad_rgb` here (two cores, `DRJIT_CACHE_DIR` set to an empty folder) takes
43 s, of which 35 s compile 17 kernels (Dr.Jit's kernel history), and 8 s once they are cached:
a first estimate on a machine pays its compilation, on either backend.

**Speed table** (Veach scene with MIS, 768x512, 64 spp, 3 rays per sample; median of 5 renders
after one to compile; ratios within the same mode):

{{table cuda_speed}}

![rays per second in cuda_ad_rgb](../images/rays-per-second-cuda.png)

In Mitsuba's default (megakernel) mode every BSDF, built-in or ours, renders at 1020-1170 Mrays/s:
the network is not what limits the GPU here. In wavefront mode all are faster in this scene
(1.6-1.7x), and the network costs 5-8 % against `roughconductor` (`opaque` weights 28 %). The `rust`
backend copies every wavefront to the host and back: 0.07x, a reference, not a way to render on
a GPU.

**Many materials** (the scene of the section above, 256x256, 16 spp, one round, wall seconds):

{{table cuda_many}}

(The one-material loads, about 0.5 s, are the process's first CUDA work; the 256 rows' `first /
one` is over the 1 rows of the other command.) Against issue 31's targets at 64 networks on the
GPU: loading 12 ms per network (target < 20 ms: met), the first render 1.55x one network's (target
2x: met), later renders 1.14x `literal`'s (target 1.1x: just above; `literal` itself compiles 64
kernels, 7.9 s for its first render). At 256 networks the shared kernel is as fast as `opaque`
weights and renders in 0.89 s, 5.5x `roughconductor`'s 0.16 s.
'''


def page(data: dict) -> str:
    return stored_page.fill(TEMPLATE, data).replace("\n\n\n", "\n\n")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools performance", description=__doc__.split("\n\n")[0])
    stored_page.add_arguments(parser, PAGE)
    args = parser.parse_args(argv)
    # Nothing here measures: with or without --stored-only the page comes from the stored tables.
    data = stored_page.data_for(args, PAGE)
    stored_page.write(args.out, page(stored_page.load(data)))
    print(f"wrote {args.out} from {data}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
