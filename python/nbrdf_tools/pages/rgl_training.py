"""docs/results/rgl-training.md: networks trained from RGL measurements directly (no MERL table),
at the trainer's defaults and at the fixed budget, against the authors' networks.

    python -m nbrdf_tools rgl-training --stored-only --out docs/results/rgl-training.md
    python -m nbrdf_tools rgl-training [--fixed-budget] [--work DIR] [--out docs/results/rgl-training.md]

The measuring run is the training report (:mod:`nbrdf_tools.pages.training`) on the RGL set with
``--rgl-fold direct``; with ``--out`` it replaces the defaults' (or, with ``--fixed-budget``, the
fixed budget's) table in ``docs/results/data/rgl-training.json`` and rewrites the page.
"""

from __future__ import annotations

import sys
from pathlib import Path

from nbrdf_tools.pages.training import Page, stored_notes, stored_table
from nbrdf_tools.pages.training import main as training_main

TEMPLATE = """# Training from RGL measurements directly

```sh
python -m nbrdf_tools rgl-training --stored-only --out docs/results/rgl-training.md
```

The command above writes this page from the stored results, `{data}`. To measure anew (each
command trains the four shared RGL measurements into `out/train_report/` and replaces its table
in that file and this page):

```sh
{defaults_command}
{fixed_command}
```

(`--rgl-fold direct`, the command's default: no MERL table; each network is `nbrdf train X.bsdf -o
X.nbrdf.json` with no other flag but `--seed 0`, the default, and `--sampling adaptive|uniform`;
the second command adds `--fixed-budget`, the paper's budget. The tables' rows are the adaptive
rows; training is deterministic for a seed.)

`nbrdf train` tells a MERL table from an RGL `.bsdf` by the first 12 bytes (`tensor_file\\0` or
the MERL header 90 90 180) and learns a measurement from `RglMeasurement::eval` at the trainer's
own sample directions: no MERL grid in between (nbrdf-core/src/source.rs).

## Results: defaults, no flags

Reference: Mitsuba's `measured` BSDF on the same file; image RMSE and SSIM of 128x128 sphere
renders under five light elevations (0-80 degrees), `python -m nbrdf_tools compare`.
Authors: their Keras networks (`../shared/data/reference-nbrdf/rgl-isotropic/`, imported with
`python -m nbrdf_mitsuba.import_keras`). Both networks have 675 weights.

Trainer defaults, the adaptive budget ([design.md section 5](../design.md#5-training-an-nbrdf)):
800,000 adaptive samples, learning rate 1e-3, up to 300 epochs, two learning-rate drops (x0.2)
after plateaus of 20 epochs, stop at a validation loss of 2e-4. Each row is
`nbrdf train X.bsdf -o X.nbrdf.json`, nothing else. Measured on {defaults_machine}.

{defaults_table}

{defaults_notes}

How the defaults were chosen (on colodur_napoli and cc_ibiza_sunset first, the two the fixed
budget lost worst; ratios are ours / authors RMSE; the networks of each row are deterministic):

{choice_table}

The same defaults were then run, unchanged, on paper_white and cc_iris_purple_gem (table above).
On MERL-format tables (SGD fits of six MERL materials, reference the table, `--fixed-budget` vs
the defaults; image RMSE, epochs, seconds on a loaded machine):

{merl_table}

{merl_notes}

## Results: the fixed budget (`--fixed-budget`)

800,000 adaptive samples, learning rate 5e-4, at most 100 epochs, patience 10 after epoch 30.
Measured on {fixed_machine}.

{fixed_table}

{fixed_notes}

## Loss decisions

{loss_notes}
* **Horizon.** The loss compares `ln(1 + f cos_light)`; `f cos_light` is what the measurement
  stores (Mitsuba's `eval`), so `f = eval / cos_light` is multiplied back by the same cosine and
  never blows up in the loss. Only the reciprocal mean's swapped term carries
  `cos_light / cos_view`; it skips samples with either cosine below 0.01 (89.4 degrees).
* **Out-of-gamut values** (slightly negative RGB of the spectral fit) are clamped to 0, as the
  `Brdf` implementation of the measurement does.

Provenance of a network trained this way records `source` (the file), `source_kind`
(`rgl-measurement` or `merl-table`) and `rgl_fold` (or `phi_fold` for tables).
"""


def render(data: dict) -> str:
    """docs/results/rgl-training.md from its stored results."""
    fields = {"data": "docs/results/data/rgl-training.json", "loss_notes": "\n".join(stored_notes(data["loss"])),
              "choice_table": "\n".join(stored_table(data["choice"]))}
    for section in ("defaults", "merl", "fixed"):
        fields[f"{section}_table"] = "\n".join(stored_table(data[section]))
        fields[f"{section}_notes"] = "\n".join(stored_notes(data[section]))
        fields[f"{section}_machine"] = data[section].get("machine", "")
        fields[f"{section}_command"] = data[section].get("command", "")
    return TEMPLATE.format(**fields).replace("\n\n\n", "\n\n")


RGL_TRAINING = Page("rgl-training", Path("docs/results/rgl-training.md"), Path("docs/results/data/rgl-training.json"),
                    render, lambda set_name, args: "fixed" if args.fixed_budget else "defaults",
                    (("set", "rgl"), ("rgl_fold", "direct")))


def main(argv: list[str] | None = None) -> int:
    return training_main(argv, RGL_TRAINING)


if __name__ == "__main__":
    sys.exit(main())
