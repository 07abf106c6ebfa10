"""Relative variance of BSDF sampling with cosine, one Blinn-Phong lobe and two lobes, per
material: synthesise the MERL material's table (``nbrdf synth --model sgd``), train its network
(``nbrdf train``), then ``nbrdf fit-phong --lobes 2 --json`` on the table and on the network,
which searches both on the same quadrature (``nbrdf-core/src/fit/lobes/``). Prints a Markdown table, stores
the rows in ``--data`` and writes the page ``--out``.

    python -m nbrdf_tools sampling --stored-only --out docs/results/sampling.md
    python -m nbrdf_tools sampling --no-train [--materials black-oxidized-steel,red-specular-plastic] [--out PAGE]

The page's scene tables (the Veach scene, ``python -m nbrdf_tools scenes``) are stored results
of those runs in the same data file; this command re-measures the quadrature only.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

from tqdm import tqdm

from nbrdf_tools.common.cli import nbrdf
from nbrdf_tools.common.paths import REPO, default_cli

PAGE = Path("docs/results/sampling.md")
DATA = Path("docs/results/data/sampling.json")

#: The issue's materials with a diffuse base under small bright lights, and three others.
DEFAULT_MATERIALS = ("black-oxidized-steel", "green-metallic-paint", "red-specular-plastic",
                     "gold-metallic-paint", "gray-plastic", "blue-metallic-paint")


# The page; {names} are filled from the stored results by report().
TEMPLATE = r"""# Sampling: cosine, one Blinn-Phong lobe, two lobes, the tabulated sampler

```sh
{opening}
```

The command above writes this page from the stored results, `{data}`. To measure the quadrature
anew ({cost} on {machine}; it rewrites the quadrature's rows in that file and this page):
`{command}`. Without `--no-train` it also trains each network (`nbrdf train`, options through
`--train-args`) and measures the network. The scene tables are stored results of the
`python -m nbrdf_tools scenes` commands shown with them.

## The quadrature: relative variance per material

Mean relative variance `R - 1` of BSDF sampling (the objective of `nbrdf fit-phong`,
[nbrdf-core/src/fit/lobes/](../../nbrdf-core/src/fit/lobes/): `int g^2/p / (int g)^2 - 1` with
`g = f_r cos`, quadrature over the half vector, averaged over 9 view elevations; lower is better,
0 is perfect). One lobe: `w phong(n) + (1 - w) cosine`, the grid search of `(n, w)`. Two lobes:
`w1 phong(n1) + w2 phong(n2) + (1 - w1 - w2) cosine`, found on the same quadrature by a coarse
grid and a pattern search started from the better of the grid and the one-lobe lobe (never
worse than one lobe). `tabulated`: the data-driven sampler below, with the cosine weight of
lowest variance among 0.1, 0.05 and 0.02 in brackets, which `fit-phong` stores; `default`: the
strategy `fit-phong` stores as the file's default. Materials: the SGD fits of the MERL materials
(`nbrdf synth --model sgd`), measured on the tables themselves; the three with a diffuse base
under small bright lights first.

{quadrature_table}

Two lobes lower the relative variance on every material, by {gain_low} to {gain_high};
`fit-phong` (default `--lobes auto`) stores them where the gain is above 2 %, here on
{stored_lobes} of {count}. The second lobe is broad (`n2 ~ 20-30`) on the paints and steel,
where it takes the diffuse-like halo that the cosine lobe covered poorly, and a second sharp
lobe on the plastics. The table samples with {table_gain} less variance than one lobe, and the
stored default is {defaults} (on this objective the default is never worse than the single lobe
by construction: the lobe is among the candidates). This is the quadrature's variance (a small
light at a random direction), not a render: the Veach scene's equal-time comparisons are below.

## The data-driven sampler `tabulated` and the per-material default

`sampling = "tabulated"` ([nbrdf-core/src/sampling/tabulated.rs](../../nbrdf-core/src/sampling/tabulated.rs), Dr.Jit
twin `jit/sampling.py` `TracedTable`): built from the material when it loads, for 16 bands of view
elevation the mass of `f_r cos` over 48 x 16 half-vector bins (`t = (1 - cos theta_h)^(1/4)` by
`|phi_h - phi_v|` over `[0, pi]`: the material is isotropic, so a bin stands for itself and its
mirror image across the plane of incidence, and one bit of a uniform picks the side; each band
the mean of the densities of three views spread from the band's lower edge, each normalised to
its own integral), the half vector uniform in solid angle within a bin, mixed with a defensive
share of cosine sampling; exact pdf; the bin is drawn through a per-row alias table (two
lookups). 16 x 48 x 16 float64 masses plus the alias tables (float64 probabilities, uint32
indices), 246 KB in memory (147 KB as float32 in the Dr.Jit twin) and nothing in the file but
the cosine weight (built in 0.1-0.3 s from a MERL table on a loaded 2-core machine: 16 x 3 views
x 48 x 16 bins x 9 evaluations). `nbrdf fit-phong` scores it on the lobe search's quadrature
with cosine weights 0.1, 0.05 and 0.02 and stores the lowest as `sampling.table_cosine_weight`
(files without it and MERL tables mix 0.1), and the lowest-variance strategy of cosine, the
stored lobe(s) and `tabulated` as `sampling.default`, which the plugin uses when the scene names
no `sampling`.

On the MERL set 48 `t` bins sample with 10-40 % less variance than 32, and 64 gain nothing more,
hence the default 48 x 16. Much of the table's advantage is the cosine weight: a glossy material
spends the cosine share where `f_r` is small, so `R - 1` of a table that follows `f_r cos` well
is close to the weight itself (`1 / (1 - c) - 1`, 0.11 at 0.1). The `t` parametrisation alone
(against `cos theta_h`, at weight 0.1) changes `R - 1` by a few percent either way
(cc_ibiza_sunset 0.083 -> 0.085, paper_white 0.015 -> 0.016).

**The grazing band.** The SGD fit of gray-plastic grows by three orders of magnitude towards
grazing `theta_d` (`f_r` 83 at `theta_d = 70` degrees, 6.2e3 at 85, 1.3e5 at 89.5, on the
normal), so a band of 84.4-90 degrees summed unnormalised is the density of its steepest view,
and views at the band's sub-band centres (85.3, 87.2, 89.1 degrees) miss the half vectors that
only the band's lower edge reflects above the horizon. `R - 1` of gray-plastic, mean and per
view at 84.4 / 84.6 / 85 degrees, for the ways of building a band:

{grazing_table}

(One lobe at these views: 1.60, 1.64, 1.74.) Finer `theta_h` bins help everywhere but
moderately: 48 bins lower the mean by 11-38 % on the six materials (red-specular-plastic 0.041 ->
0.025), 64 bins gain nothing over 48 (0.026-0.043), 48 x 48 bins 3-11 % more (1.5x the memory);
24 rows instead of 16 lower gray-plastic by 21 % and raise the others by 1-3 %. The Rust test
`every_view_of_the_grazing_band_samples_better_than_one_lobe` holds the table below the lobe at
views 84.4-89.5 degrees on the SGD gray-plastic.

## MERL materials in the Veach scene: against one lobe, and the stored default

```sh
python -m nbrdf_tools scenes --scene veach --integrator bsdf --rgl "" \
    --materials {merl_materials} \
    --strategies phong-fit,two-lobe-fit,tabulated,default --width 256 --max-spp 32 --seeds 8 --gt-spp 512 \
    --train-args "--epochs 20 --samples 200000"
```

The six materials of the quadrature, with the table above. Networks: `nbrdf train` on the
SGD-synthesised table with a short budget (20 epochs, 200k samples), then `nbrdf fit-phong
--lobes 1` (`phong-fit`) and `--lobes 2` (the two-lobe mixture, `sampling.default` and
`sampling.table_cosine_weight`, stored in the file). `default` is the plugin with no `sampling`
at all, i.e. the file's `sampling.default`: the same sampler as `tabulated` on five materials,
so `tabulated` and `default` are two independent runs of one sampler and their difference shows
the noise of these settings. Pure BSDF sampling, 256x171, 1-32 spp, 8 seeds, references at 512
spp; 3 minutes with networks and references cached, on {merl_machine}. RMSE over `phong-fit`'s
at equal time (the longest time all strategies reached, 0.07-0.08 s, where `phong-fit` has 32
spp), median of 8 seeds; then two figures that use the whole curve instead of its last point,
for `tabulated` / `default`: the RMSE ratio at equal spp and `sqrt(RMSE^2 x time)` (efficiency),
both geometric means over 4-32 spp of the 8-seed medians; last, the prediction of the
quadrature, `sqrt(R_table / R_lobe)` with `R` = relative variance + 1 of the network
(`fit-phong`'s figures):

{merl_table}

* **The stored default is better than one lobe in the scene on four materials (0.89-0.96 at
  equal time), level on red-specular-plastic** (the default is cosine there, and so is every
  strategy, below) **and behind on black-oxidized-steel at this equal-time point (1.18; the table
  1.13)**. That point is `phong-fit`'s 32 spp render, whose median RMSE falls faster from 16 to
  32 spp than its curve does elsewhere: heavy-tailed noise on one curve. Over the whole curve the
  table is ahead on steel too (0.92-0.94 at equal spp, 0.92-0.96 in efficiency), and at larger
  settings it is ahead at the equal-time point as well:
* **Black-oxidized-steel at larger settings: the default is level with one lobe (0.99).** The
  same material alone, 384x256, 1-256 spp, 8 seeds, references at 1024 spp (1 minute with the
  network cached):

  ```sh
  python -m nbrdf_tools scenes --scene veach --integrator bsdf --rgl "" \
      --materials black-oxidized-steel --strategies phong-fit,tabulated --width 384 --max-spp 256 \
      --seeds 8 --gt-spp 1024 --train-args "--epochs 20 --samples 200000"
  ```

  gives `tabulated` (the stored default) / `phong-fit` = **0.99** at equal time (1.07 s, 256
  spp), and 0.93-0.98 at equal spp from 32 to 256 spp (0.1296 / 0.1361, 0.0911 / 0.0984,
  0.0669 / 0.0690, 0.0473 / 0.0483; only the 16 spp point is above, 1.12), the table's renders
  taking 1.01-1.02x the lobe's time. So "never worse than one lobe in the scene" holds on all six
  within the seeds' spread (0.89-1.00 at equal time, steel at the larger settings).
* **Why the scene gains 5-15 %, not the several-fold of the quadrature.** The quadrature ranks
  by the relative variance `R - 1`, the variance under a uniformly bright sky; a small light at a
  random direction sees the second moment `R` (fit/lobes: the estimate hits the light with
  probability `p Omega` and its variance is `L^2 Omega int g^2 / p`, the mean's square being
  `O(Omega^2)`). `R` of the lobes and the table differ little (steel 1.24 against 1.02), and
  `sqrt(R_table / R_lobe)` predicts the scene's equal-spp ratio within 10 % on all six
  (0.85-1.01 predicted, 0.81-0.97 measured). Ranking by `R` or by `R - 1` picks the same strategy
  (they differ by 1 per view), so the selection itself does not change. The objective does not
  see the cost per sample, but since the table draws its bin through an alias table and its pdf
  needs no elevation arc tangent, its renders take 0.96-1.06x the lobe's time, so ranking by
  variance alone keeps almost all of its gain at equal time.
* The networks here are briefly trained: red-specular-plastic's lost its spike (representation
  relative RMSE 0.44; `fit-phong` finds every lobe weight 0 and `R - 1` of 7e-4 for cosine), so
  `phong-fit` and `two-lobe-fit` are cosine sampling and the stored default is `cosine`, level
  with them in the scene (the table 0.97-1.00).
* The two-lobe mixture is level with one lobe in this scene (0.99-1.01 on five), as in the RGL
  runs below; worse on steel (1.26, same caveat as the table).

## Veach scene, RGL measurements: against Mitsuba's `measured`

```sh
python -m nbrdf_tools scenes --scene veach --integrator bsdf --materials "" \
    --rgl paper_white_rgb,cc_ibiza_sunset_rgb,cc_iris_purple_gem_rgb,colodur_napoli_4f_rgb \
    --strategies cosine,phong-fit,two-lobe-fit,tabulated,measured --width 384 --max-spp 64 --seeds 6 --gt-spp 1024
```

(`--rgl` takes names in the shared data, as here, or paths of `.bsdf` files.) Pure BSDF sampling
(`direct`, no emitter samples), 384x256, 1-64 spp, 6 seeds, references at 1024 spp with MIS;
about 2 minutes with the networks cached (5 with training), measured {rgl_date} on
{rgl_machine}. Networks: `nbrdf train X.bsdf` with its defaults, trained on the measurement
itself; lobes: `nbrdf fit-phong --lobes 1` (`phong-fit`) and `--lobes 2` (`two-lobe-fit`);
`tabulated` is the table of this page, and `fit-phong` stores it as the default of all four,
with the cosine weight of lowest variance (0.02 on the two paints, 0.1 on the near-diffuse two;
relative variance `R - 1` 0.032 / 0.036 / 0.017 / 0.016 on cc_ibiza_sunset / cc_iris_purple_gem
/ colodur_napoli / paper_white, against 0.50 / 0.38 / 0.10 / 0.04 for the best lobe mixture).
Each strategy's error is measured against the converged render of its own BSDF (the NBRDF for
ours, the measurement for `measured`), on the plates. Equal time: the longest render time every
strategy reached (0.18-0.19 s on this machine, where ours reach 64 spp), read off each
strategy's log-log curve of the median RMSE over seeds; in brackets the root mean square over
seeds. Ratio to `measured`'s RMSE (below 1 is better than `measured`), two runs of the command
back to back (the renders are the same, seeded; only their timings differ), the second in
brackets where it differs by more than 0.005:

{rgl_table}

The run-to-run spread of these ratios is about +-0.03 on a quiet machine and +-0.05 under load,
from render timings alone.

{rgl_figure}

Per sample and per render, and the cost floor (the run's `summary.md`, `cost_floor` in
`convergence.json`; first run, the second in brackets where it differs). At 64 spp, median over
the 6 seeds: each strategy's RMSE / render time, both over `measured`'s. `diffuse` time: the
same renders with `diffuse` plates, timed in the same interleaved runs: a BSDF that costs next
to nothing, so this is the scene's share of every render (rays, lights, film). Bound: the
equal-time ratio the best per-sample error reaches if its BSDF cost nothing, per-sample ratio x
sqrt(`diffuse` time):

{cost_table}

Against the target of the best NBRDF strategy at 0.8x `measured`'s RMSE or less at equal time:

* **Reached on colodur_napoli_4f (0.76); not on paper_white (0.81-0.82) and the glossy paints
  (0.83-0.85).** Better than `measured` by 15-24 % at equal time on all four, but not by 20 % on
  three.
* **The target is at the floor of what any BSDF can reach in this scene.** `diffuse` plates
  render in 0.66-0.69x `measured`'s time: two thirds of `measured`'s render is the scene's, not
  its BSDF's. A BSDF that cost nothing to evaluate and to sample would reach, at our per-sample
  error, 0.79-0.81 on the three materials (the bound column): at the line, not below it. Our
  BSDF's own cost (network and sampler) is 0.04-0.07 of `measured`'s render time; all of it
  would have to go.
* **Per sample there is little left to win.** The table samples the paints with 1-3 % less
  error per sample than `measured`'s data-driven warp, the near-diffuse ones with 2-4 % less
  (as does cosine). Its `R` is 1.03-1.04 on the paints against 1 for a perfect sampler of
  `f cos` (cosine's is 1.05 on paper_white), so a perfect sampler would lower the per-sample
  RMSE by about 1.5-2.5 % more; the rest of the per-sample ratio is the two BSDFs themselves
  (the variance of hitting a small light with a perfect sampler depends on the lobe's shape).
  A perfect sampler that cost nothing, with the network's evaluation as the only cost (cosine
  sampling's time, 0.69-0.71x), would give about 0.79-0.81 on the three; only if the network
  cost nothing as well would it reach 0.77-0.80, 0-0.03 below the line: about the runs' spread.
  The table's cosine weight at 0.02 instead of 0.1 (stored by `fit-phong` on the paints) lowers
  `R - 1` from 0.085 to 0.032 and from 0.093 to 0.036 but does not show in the scene (0.971 ->
  0.973 and 0.951 -> 0.963 per sample, within the seeds' spread).
* **Where the time goes.** The renders take 0.72-0.76x `measured`'s time (the slope between 32
  and 64 spp, free of the per-render overhead, is 0.71x), split about evenly between the network
  (cosine sampling, which costs next to nothing to draw, renders in 0.69-0.71x) and the table;
  the speed table ([performance.md](performance.md)) has `nbrdf` at 1.34x `measured`'s
  rays/sec. A network of a third of the weights renders in 0.70-0.71x and doubles the
  representation error, a cheaper table gains 0.01 ([experiments.md](../experiments.md)).
  Reaching 0.8 with a margin needs a scene where the BSDF is a larger part of the cost, not a
  better sampler.
* The stored default (`tabulated` on all four, by the quadrature) is the best strategy in the
  scene on the paints, and within 0.03-0.05 of cosine on the near-diffuse ones; the table's
  renders take 1.02-1.08x cosine's time, so ranking by variance alone (not variance x cost)
  costs little.
"""

def _variances(cli: Path, material_file: Path, *extra) -> dict:
    report = json.loads(nbrdf(cli, "fit-phong", material_file, "--lobes", "2", "--json", *extra))
    variance, two = report["relative_variance"], report["two_lobe"]
    return {"cosine": variance["cosine"], "one_lobe": variance["variance_lobe"], "two_lobe": variance["two_lobe"],
            "tabulated": variance["tabulated"], "table_cosine_weight": report["table_cosine_weight"],
            "default": report["default_sampling"],
            "two_lobe_n": two["exponents"], "two_lobe_w": two["weights"]}


def measure(cli: Path, material: str, work: Path, train_args: list[str] | None) -> list[dict]:
    """Rows for the material's table and, unless ``train_args`` is None, its trained network."""
    table = work / f"{material}.binary"
    nbrdf(cli, "synth", "--model", "sgd", "--material", material, "-o", table)
    rows = [{"material": material, "of": "table", **_variances(cli, table)}]
    if train_args is not None:
        network = work / f"{material}.nbrdf.json"
        nbrdf(cli, "train", table, "-o", network, "-q", *train_args)
        rows.append({"material": material, "of": "network", **_variances(cli, network, "-o", work / "fit.json")})
    table.unlink()
    return rows


def markdown(rows: list[dict]) -> str:
    lines = ["| material | of | cosine | one lobe | two lobes | tabulated (cosine weight) | two/one | tabulated/one "
             "| default | two lobes (n1, w1; n2, w2) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        n, w = r["two_lobe_n"], r["two_lobe_w"]
        lines.append(f"| {r['material']} | {r['of']} | {r['cosine']:.3g} | {r['one_lobe']:.3g} | {r['two_lobe']:.3g} | "
                     f"{r['tabulated']:.3g} ({r['table_cosine_weight']:.2g}) | {r['two_lobe'] / r['one_lobe']:.2f} | "
                     f"{r['tabulated'] / r['one_lobe']:.2f} | {r['default']} | "
                     f"{n[0]:.3g}, {w[0]:.2f}; {n[1]:.3g}, {w[1]:.2f} |")
    return "\n".join(lines)


def table(stored: dict) -> str:
    """A stored table (``columns``, ``rows`` of cells) in Markdown."""
    lines = ["| " + " | ".join(stored["columns"]) + " |", "|" + "---|" * len(stored["columns"])]
    return "\n".join(lines + ["| " + " | ".join(row) + " |" for row in stored["rows"]])


def report(data: dict) -> str:
    """The page, from the stored results alone."""
    quadrature = data["quadrature"]
    rows = [r for r in quadrature["rows"] if r["of"] == "table"]
    gains = sorted((1 - r["two_lobe"] / r["one_lobe"], r["material"]) for r in rows)
    table_gain = [r["one_lobe"] / r["tabulated"] for r in rows]
    defaults = sorted({r["default"] for r in rows})
    figures = {
        "opening": f"python -m nbrdf_tools sampling --stored-only --out {PAGE}", "data": str(DATA),
        "command": quadrature["command"], "cost": quadrature["cost"], "machine": quadrature["machine"],
        "quadrature_table": markdown(quadrature["rows"]), "count": len(rows),
        "gain_low": f"{100 * gains[0][0]:.0f} % ({gains[0][1]})",
        "gain_high": f"{100 * gains[-1][0]:.0f} % ({gains[-1][1]})",
        "merl_materials": ",".join(DEFAULT_MATERIALS),
        "rgl_figure": "![RMSE on the plates against render time for the four RGL materials: cosine, phong-fit, "
                      "two-lobe-fit, tabulated and measured, median of 6 seeds with min-max bands]"
                      "(../images/sampling-rgl-vs-measured.png)",
        "stored_lobes": sum(1 - r["two_lobe"] / r["one_lobe"] > 0.02 for r in rows),
        "table_gain": f"{min(table_gain):.0f}-{max(table_gain):.0f}x",
        "defaults": " or ".join(f"`{d}`" for d in defaults),
        "grazing_table": table(data["grazing_band"]),
        "merl_machine": data["veach_merl"]["machine"], "merl_table": table(data["veach_merl"]),
        "rgl_date": data["veach_rgl"]["date"], "rgl_machine": data["veach_rgl"]["machine"],
        "rgl_table": table(data["veach_rgl"]), "cost_table": table(data["veach_rgl_cost"]),
    }
    return TEMPLATE.format(**figures)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m nbrdf_tools sampling", description=__doc__.split("\n\n")[0])
    parser.add_argument("--materials", default=",".join(DEFAULT_MATERIALS), help="comma-separated MERL names")
    parser.add_argument("--cli", type=Path, default=None, help="the nbrdf binary (default: the build's)")
    parser.add_argument("--train-args", default="", help="extra `nbrdf train` options, e.g. '--samples 200000'")
    parser.add_argument("--no-train", action="store_true", help="measure the synthesised tables only")
    parser.add_argument("--json", type=Path, default=None, help="also write the rows here")
    parser.add_argument("--out", type=Path, default=REPO / PAGE, help=f"the Markdown page (default: {PAGE})")
    parser.add_argument("--data", type=Path, default=REPO / DATA,
                        help=f"the stored results, read with --stored-only, else updated (default: {DATA})")
    parser.add_argument("--stored-only", action="store_true",
                        help="write the page from the stored results, measuring nothing")
    args = parser.parse_args(argv)
    data = json.loads(args.data.read_text())
    if not args.stored_only:
        cli = args.cli or default_cli()
        rows = []
        with tempfile.TemporaryDirectory() as tmp:
            for material in tqdm(args.materials.split(","), desc="materials", file=sys.stderr):
                train_args = None if args.no_train else args.train_args.split()
                rows += measure(cli, material.strip(), Path(tmp), train_args)
        print(markdown(rows))
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
        words = ["python -m nbrdf_tools sampling", *(["--no-train"] if args.no_train else []),
                 *(["--materials", args.materials] if args.materials != ",".join(DEFAULT_MATERIALS) else []),
                 *(["--train-args", repr(args.train_args)] if args.train_args else []), "--out", str(PAGE)]
        data["quadrature"].update(command=" ".join(words), machine=f"{os.cpu_count()} cores", rows=rows)
        args.data.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n")
    args.out.write_text(report(data))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
