"""Results pages regenerated from stored data: each page of docs/results keeps what it reports in
``docs/results/data/PAGE.json``, and its generator's ``--stored-only`` path writes the whole page
from that file without measuring anything."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from nbrdf_tools.common.paths import REPO

RESULTS = REPO / "docs" / "results"
DATA = RESULTS / "data"


def data_path(page: str) -> Path:
    """The stored data of ``docs/results/PAGE.md``."""
    return DATA / f"{page}.json"


def page_path(page: str) -> Path:
    return RESULTS / f"{page}.md"


def load(path: Path) -> dict:
    return json.loads(Path(path).read_text(encoding="utf-8"))


def save(path: Path, data: dict) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1, ensure_ascii=False) + "\n", encoding="utf-8")
    return path


def write(path: Path, text: str) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def add_arguments(parser: argparse.ArgumentParser, page: str, out: bool = True) -> None:
    """``--stored-only`` and ``--data`` (and ``--out``, the page, unless the command has its own)."""
    parser.add_argument("--stored-only", action="store_true",
                        help=f"measure nothing: write the page from the stored data ({data_path(page).relative_to(REPO)})")
    parser.add_argument("--data", type=Path,
                        help=f"the stored data the page is written from (default: {data_path(page).relative_to(REPO)}, "
                             "or beside --out when a measuring run writes its page elsewhere)")
    if out:
        parser.add_argument("--out", type=Path, default=page_path(page), help="the page (default: %(default)s)")


def data_for(args: argparse.Namespace, page: str) -> Path:
    """``--data``, else the page's stored data; a measuring run whose ``--out`` is not the page
    itself keeps its data beside that file instead (a test or trial run leaves the record alone)."""
    if args.data is not None:
        return args.data
    out = getattr(args, "out", None)
    if args.stored_only or out is None or Path(out).resolve() == page_path(page):
        return data_path(page)
    return Path(out).with_suffix(".json")


def _shown(path: Path) -> str:
    path = Path(path).resolve()
    return str(path.relative_to(REPO)) if path.is_relative_to(REPO) else str(path)


def opening_command(page: str, out: Path | None = None, data: Path | None = None) -> str:
    """The command that writes the page from its data: ``python -m nbrdf_tools PAGE --stored-only
    --out docs/results/PAGE.md`` for the page itself, with ``--data`` only where it is not the default."""
    out, data = out or page_path(page), data or data_path(page)
    extra = "" if Path(data).resolve() == data_path(page) else f" --data {_shown(data)}"
    return f"python -m nbrdf_tools {page} --stored-only{extra} --out {_shown(out)}"


def link(target: str | Path, page: str) -> str:
    """``target`` (relative to the repository) as a link from ``docs/results/PAGE.md``, wherever
    the page is written."""
    return os.path.relpath(REPO / target, page_path(page).parent)


def table(spec: dict) -> list[str]:
    """A Markdown table from ``{"columns": [...], "align": "lr...", "rows": [[...], ...]}``
    (``l`` left, ``r`` right; the cells as stored)."""
    columns, align = spec["columns"], spec.get("align") or "l" * len(spec["columns"])
    lines = ["| " + " | ".join(columns) + " |", "|" + "".join("---:|" if a == "r" else "---|" for a in align)]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in spec["rows"]]
    return lines


def fill(template: str, data: dict) -> str:
    """``template`` with each ``{{table NAME}}`` line replaced by ``data["tables"][NAME]`` (see
    :func:`table`) and each ``{{text NAME}}`` by ``data["texts"][NAME]``: the figures and what they
    show stay in the data, the method in the generator."""
    lines = []
    for line in template.splitlines():
        key = line.strip()
        if key.startswith("{{table ") and key.endswith("}}"):
            lines += table(data["tables"][key[8:-2]])
        elif key.startswith("{{text ") and key.endswith("}}"):
            lines.append(data["texts"][key[7:-2]])
        else:
            lines.append(line)
    return "\n".join(lines) + "\n"
