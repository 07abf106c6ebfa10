"""docs/results/latent.md from its stored data, docs/results/data/latent.json (the tables, and
under ``runs`` the settings and selections they came from); the prose in
``pages/templates/latent.md``. A measuring run of ``python -m nbrdf_tools latent`` replaces its
set's autoencoder-against-PCA table and run settings (:func:`update`)."""

from __future__ import annotations

import datetime
import os
import platform
from importlib import resources
from pathlib import Path

from nbrdf_tools.common import stored_page

PAGE = "latent"

# The paper's figures (Sztrajman et al. 2021, real MERL data, its own renders), beside the real set.
PAPER_ROW = ["the paper: autoencoder / PCA-32 (real MERL data, its own renders)", "0.0178 / 0.0199", "-",
             "0.968 / 0.982"]


def template() -> str:
    return resources.files("nbrdf_tools.pages").joinpath("templates", f"{PAGE}.md").read_text(encoding="utf-8")


def _cell(stats: dict, digits: int, bold: bool) -> str:
    mean = f"{stats['mean']:.{digits}f}"
    return f"{f'**{mean}**' if bold else mean} ± {stats['std']:.{digits}f} ({stats['median']:.{digits}f})"


def ae_vs_pca_table(ev: dict, source: str) -> dict:
    """The summary of ``nbrdf ae eval``: mean ± sd (median) of MAE, RMSE and SSIM per method."""
    s = ev["summary"]
    methods = [("ae", "autoencoder (32), encoder's code", False),
               ("ae_refined", "**autoencoder (32), refined code**", True),
               ("pca", "PCA-32" if ev["pca"]["tables"] == "nbrdf" else "PCA-32 (SGD tables)", False)]
    rows = [[label, *(_cell(s[key][m], 3 if m == "ssim" else 5, bold) for m in ("mae", "rmse", "ssim"))]
            for key, label, bold in methods if key in s]
    if source == "authors":
        rows.append(PAPER_ROW)
    return {"columns": ["method", "MAE", "RMSE", "SSIM"], "align": "llll", "rows": rows}


def wins(ev: dict) -> dict | None:
    """Per material, how often the refined autoencoder beats PCA-32."""
    m = ev["materials"]
    if "ae_refined" not in m[0]:
        return None
    count = {q: sum(better(r["ae_refined"][q], r["pca"][q]) for r in m)
             for q, better in (("mae", float.__lt__), ("rmse", float.__lt__), ("ssim", float.__gt__))}
    return {**count, "of": len(m)}


def selection(provenance: dict) -> dict | None:
    """The chosen seed's refined validation loss and the others' (AE.json ``provenance.selection``)."""
    chosen = provenance.get("selection")
    if not chosen:
        return None
    candidates = sorted(chosen["candidates"], key=lambda c: c["refined_validation_loss"])
    return {"chosen": candidates[0]["seed"], "loss": candidates[0]["refined_validation_loss"],
            "others": [c["refined_validation_loss"] for c in candidates[1:]]}


def update(data: dict, ev: dict, provenance: dict, source: str, command: str, refine: int) -> None:
    """Put a run's autoencoder-against-PCA table and settings into ``data``."""
    data.setdefault("tables", {})[f"ae_vs_pca_{source}"] = ae_vs_pca_table(ev, source)
    run = {"date": datetime.date.today().isoformat(), "command": command,
           "machine": f"{os.cpu_count()}-core CPU ({platform.machine()}, {platform.system()})",
           "refine": refine or None, "selection": selection(provenance), "wins": wins(ev)}
    data.setdefault("runs", {})[source] = {k: v for k, v in run.items() if v is not None}


def _loss(value: float) -> str:
    mantissa, exponent = f"{value:.2e}".split("e")
    return f"{mantissa.rstrip('0').rstrip('.')}e{int(exponent)}"


def describe_run(run: dict) -> str:
    parts = [f"*Measured* by `{run['command']}`" + (f" on {run['date']}" if run.get("date") else "")
             + (f" ({run['machine']})" if run.get("machine") else "")]
    if run.get("refine"):
        parts.append(f"codes refined with {run['refine']} iterations")
    if run.get("selection"):
        s = run["selection"]
        others = " and ".join(_loss(loss) for loss in s["others"])
        parts.append(f"seed {s['chosen']} chosen (refined validation loss {_loss(s['loss'])}"
                     + (f", against {others} for the other seeds)" if others else ")"))
    if run.get("wins"):
        w = run["wins"]
        parts.append(f"refined autoencoder better than PCA-32 on MAE for {w['mae']}, RMSE {w['rmse']}, "
                     f"SSIM {w['ssim']} of the {w['of']} materials")
    return "; ".join(parts) + "."


def page(data: dict) -> str:
    texts = {f"run:{key}": describe_run(run) for key, run in data["runs"].items() if "command" in run}
    texts["run:timing"] = f"*Measured* on a {data['runs']['timing']['machine']}."
    return stored_page.fill(template(), {"tables": data["tables"], "texts": texts})


def write_stored(out, data_file=None) -> None:
    """The page from its stored data (``--stored-only``)."""
    data_file = data_file or stored_page.data_path(PAGE)
    stored_page.write(out or stored_page.page_path(PAGE), page(stored_page.load(data_file)))
    print(f"wrote {out or stored_page.page_path(PAGE)} from {data_file}")


def files_of_run(data: Path | None, out_given: Path | None, out: Path) -> tuple[Path, Path]:
    """(data, page) a measuring run updates: ``data`` if given; else the stored data and the
    results page when the run used the default output folder, ``OUT/latent.json`` and
    ``OUT/latent.md`` when it was given its own (trial runs leave the record alone)."""
    record = stored_page.data_path(PAGE)
    data = Path(data) if data is not None else record if out_given is None else Path(out) / f"{PAGE}.json"
    return data, stored_page.page_path(PAGE) if data.resolve() == record else data.with_suffix(".md")


def write_measured(ev: dict, provenance: dict, source: str, command: str, refine: int, data_file: Path,
                   page_file: Path) -> None:
    """Put a run's results into ``data_file`` (starting from the stored data when it is not there
    yet) and write the page from it."""
    data_file = Path(data_file)
    data = stored_page.load(data_file if data_file.is_file() else stored_page.data_path(PAGE))
    update(data, ev, provenance, source, command, refine)
    stored_page.save(data_file, data)
    stored_page.write(page_file, page(data))
    print(f"updated the {source} set in {data_file}; wrote {page_file}")
