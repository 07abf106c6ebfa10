"""Neural textures: textured Mitsuba BSDFs (a kitchen material, blends of two RGL measurements by
a mask, textured ``principled`` and ``roughconductor``) distilled into a decoder and a latent
texture, rendered beside their sources under views and lights no training saw.

    python -m nbrdf_tools neural-textures --stored-only --out docs/results/neural-textures.md
    python -m nbrdf_tools neural-textures [--set test|tuning|all] [--sources NAME ...] [--work out/neural-textures]
        [--resolution 256] [--size 256] [--spp 16] [--no-kitchen] [--quick]

The sources (:mod:`.sources`) are split once: the tuning set is where the distiller's defaults
may be chosen, the test set is what the page's headline reports. For each source: the
conversion (``python -m nbrdf_mitsuba.distill SOURCE --spatial``, seconds on this machine), renders
of the source, of the neural texture and, for blends, of the per-material route (the same blend
over per-material networks of the two measurements) that trace the same paths, with the
tone-mapped RMSE and HDR-FLIP of the latter two against the source's; rays per second of the source, the neural texture and
``roughconductor`` in the same scene; memory; Mitsuba's chi2 test at several texels. Then the
kitchen with its textured materials replaced by their neural textures beside the original.
Writes the data (``--data``, default docs/results/data/neural-textures.json), pictures beside it
and the page.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from nbrdf_tools.common import stored_page
from nbrdf_tools.common.paths import REPO

from . import page as page_module
from .page import PAGE

def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m nbrdf_tools neural-textures", description=__doc__.split("\n\n")[0])
    stored_page.add_arguments(p, PAGE)
    p.add_argument("--set", dest="subset", default="all", choices=("test", "tuning", "all"),
                   help="which sources (default: all; the headline reports the test set)")
    p.add_argument("--sources", nargs="+", metavar="NAME", help="only these sources")
    p.add_argument("--work", type=Path, default=REPO / "out" / "neural-textures", help="work folder")
    p.add_argument("--resolution", type=int, default=256, help="the neural textures' size (default: 256)")
    p.add_argument("--channels", type=int, help="latent channels (default: the distiller's)")
    p.add_argument("--size", type=int, default=256, help="render width in pixels (default: 256)")
    p.add_argument("--spp", type=int, default=16, help="samples per pixel of the compared renders (default: 16)")
    p.add_argument("--repeats", type=int, default=5, help="timed renders per BSDF, the best kept (default: 5)")
    p.add_argument("--no-kitchen", action="store_true", help="skip the kitchen comparison")
    p.add_argument("--quick", action="store_true", help="tiny textures, renders and training (a smoke test)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    data_path = stored_page.data_for(args, PAGE)
    # The page names its own path, wherever this run writes it (a check regenerates it elsewhere).
    opening = stored_page.opening_command(PAGE, None, data_path)
    if not args.stored_only:
        from .run import measure_all

        stored_page.save(data_path, measure_all(args, data_path.parent))
    data = stored_page.load(data_path)
    stored_page.write(args.out, page_module.page(data, opening))
    print(f"wrote {args.out} from {data_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
