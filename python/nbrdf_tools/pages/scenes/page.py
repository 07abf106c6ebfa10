"""docs/results/scenes.md from its stored data, docs/results/data/scenes.json: the tables and the
settings of each run (``runs``) there, the prose in ``pages/templates/scenes.md``."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from nbrdf_tools.common import stored_page
from nbrdf_tools.pages.scenes import record

PAGE = "scenes"


def template() -> str:
    return resources.files("nbrdf_tools.pages").joinpath("templates", f"{PAGE}.md").read_text(encoding="utf-8")


def describe_run(run: dict) -> str:
    """One line: the settings and machine a section's figures were measured under."""
    (width, height), (low, high) = run["resolution"], run["spp"]
    seeds = f"{run['seeds']} seed{'s' if run['seeds'] != 1 else ''}"
    training = ("`nbrdf train` (default recipe)" if run["training"] == "default recipe"
                else f"`nbrdf train {run['training']}`")
    when = ", ".join(part for part in (run.get("date"),
                                       f"{run['seconds']:.0f} s" if run.get("seconds") else None) if part)
    return (f"*Measured at* {width}x{height}, {low}–{high} spp, references at {run['gt_spp']} spp, {seeds}; "
            f"`{run['variant']}` on a {run['machine']}; networks from {training}"
            + (f"; {when}." if when else "."))


def describe_checks(run: dict) -> str:
    """The kitchen's checks for non-finite values and fireflies."""
    c = run["checks"]
    nonfinite = ("no non-finite value" if c["nonfinite"] == 0 else f"{c['nonfinite']} non-finite values")
    text = (f"Checks: {nonfinite} in the strategy renders, the converged NBRDF and the Phong-sampled "
            f"{c['spp']} spp renders of the NBRDF and of the table (same random numbers); fireflies there "
            f"(luminance above 10 × ground truth + 1): {c['fireflies_nbrdf']} (NBRDF) and {c['fireflies_table']} "
            f"(table) of {c['pixels']:,} pixels.")
    if c.get("replaced_percent") is not None:
        text += f" The replaced materials cover {c['replaced_percent']:.0f} % of the image."
    if run.get("representation"):
        r = run["representation"]
        text += (f" Representation error of these networks: RMSE {r['rmse']:.2g} on the image "
                 f"(relative {100 * r['relative_rmse']:.1f} %).")
    return text


def page(data: dict) -> str:
    texts = {f"run:{key}": describe_run(run) for key, run in data["runs"].items()}
    texts.update({f"checks:{key}": describe_checks(run) for key, run in data["runs"].items() if "checks" in run})
    return stored_page.fill(template(), {"tables": data["tables"], "texts": texts})


def write_stored(out, data_file=None) -> None:
    """The page from its stored data (``--stored-only``)."""
    data_file = data_file or stored_page.data_path(PAGE)
    stored_page.write(out or stored_page.page_path(PAGE), page(stored_page.load(data_file)))
    print(f"wrote {out or stored_page.page_path(PAGE)} from {data_file}")


def files_of_run(args, out: Path) -> tuple[Path, Path]:
    """(data, page) a measuring run updates: ``--data`` (its page beside it, or the results page
    for the stored data itself); else the stored data and the results page for a full run with the
    default output folder, and ``out/scenes.json`` and ``out/scenes.md`` (the run's folder) for a quick run or one
    with its own ``--out``, so that trial runs leave the record alone."""
    record_data = stored_page.data_path(PAGE)
    if args.data is not None:
        data = Path(args.data)
    elif args.out is None and not args.quick:
        data = record_data
    else:
        data = Path(out) / f"{PAGE}.json"
    page_file = stored_page.page_path(PAGE) if data.resolve() == record_data else data.with_suffix(".md")
    return data, page_file


def write_measured(report: dict, data_file: Path, page_file: Path) -> str:
    """Put a run's tables and settings into ``data_file`` (starting from the stored data when it is
    not there yet) and write the page from it; the key of the section replaced."""
    data_file = Path(data_file)
    data = stored_page.load(data_file if data_file.is_file() else stored_page.data_path(PAGE))
    key = record.update(data, report)
    stored_page.save(data_file, data)
    stored_page.write(page_file, page(data))
    print(f"updated '{key}' in {data_file}; wrote {page_file}")
    return key
