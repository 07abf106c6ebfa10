"""The performance page, docs/results/performance.md, from the benchmark results stored in
docs/results/data/performance.json (the tables of ``python -m nbrdf_tools bench-rays --json``,
``python -m nbrdf_tools bench-many --json`` and the criterion figures of ``make bench``, each
table's source named in the file's ``sources``). It measures nothing: the benchmarks the page
names are the way to measure anew, and their figures go into the data file's tables.

    python -m nbrdf_tools performance --stored-only --out docs/results/performance.md
"""

from __future__ import annotations

import argparse
import sys
from importlib import resources

from nbrdf_tools.common import stored_page

PAGE = "performance"


def template() -> str:
    """The page's prose; each {{table NAME}} line is the stored table NAME."""
    return resources.files("nbrdf_tools.pages").joinpath("templates", f"{PAGE}.md").read_text(encoding="utf-8")


def page(data: dict) -> str:
    return stored_page.fill(template(), data).replace("\n\n\n", "\n\n")


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
