"""``python -m nbrdf_tools COMMAND ...``: every command of the tools package, listed by kind."""

from __future__ import annotations

import importlib
import sys

# name -> (module with a ``main(argv)``, one line); grouped as the listing shows them.
GROUPS = {
    "user commands": {
        "demo": ("nbrdf_tools.demo", "make demo: one material's table and network rendered side by side"),
        "library": ("nbrdf_tools.library.main", "a whole material library into networks, resumable, local or Dask"),
        "compare": ("nbrdf_tools.common.compare_materials", "compare two materials (table, network, RGL, BSDF)"),
    },
    "results pages (docs/results/NAME.md)": {
        "anisotropic": ("nbrdf_tools.pages.anisotropic", "anisotropic distillation on turned surfaces"),
        "distill": ("nbrdf_tools.pages.distill", "Mitsuba BSDFs distilled into networks"),
        "estimation": ("nbrdf_tools.pages.estimation", "material estimation from images"),
        "estimation-seeds": ("nbrdf_tools.pages.estimation.seeds", "the estimation report's means over seeds"),
        "estimation-convergence": ("nbrdf_tools.pages.estimation.convergence",
                                   "the estimation report's loss curves"),
        "fidelity": ("nbrdf_tools.pages.fidelity", "NBRDFs against analytic fits and the measurement"),
        "latent": ("nbrdf_tools.pages.latent", "the latent space of materials"),
        "neural-textures": ("nbrdf_tools.pages.neural_textures", "textured BSDFs as a decoder and a latent texture"),
        "performance": ("nbrdf_tools.pages.performance", "speed, rays per second, many materials"),
        "rgl-training": ("nbrdf_tools.pages.rgl_training", "training NBRDFs from RGL measurements directly"),
        "sampling": ("nbrdf_tools.pages.sampling", "sampling variance: cosine, one lobe, two lobes"),
        "scenes": ("nbrdf_tools.pages.scenes", "sampling in scenes: convergence against spp and time"),
        "spectral-basis": ("nbrdf_tools.pages.spectral_basis", "spectral output representations"),
        "spectral-networks": ("nbrdf_tools.pages.spectral_networks", "spectral networks"),
        "training": ("nbrdf_tools.pages.training", "training NBRDFs: trainer speed, SGD tables, RGL tables"),
        "variants": ("nbrdf_tools.pages.variants", "the Veach scene in every variant"),
    },
    "benchmarks": {
        "bench-rays": ("nbrdf_tools.bench.rays", "rays per second against Mitsuba's built-in BSDFs"),
        "bench-many": ("nbrdf_tools.bench.many", "scenes with many different materials"),
        "library-overhead": ("nbrdf_tools.library.overhead", "the library executors' own cost per material"),
    },
    "data": {
        "pretrained": ("nbrdf_tools.data.pretrained", "the pretrained models the nbrdf command embeds"),
        "spectral-rgl": ("nbrdf_tools.data.spectral_rgl", "a spectral RGL measurement from an RGB one"),
    },
}
COMMANDS = {name: entry for group in GROUPS.values() for name, entry in group.items()}


def usage() -> str:
    lines = ["usage: python -m nbrdf_tools COMMAND [ARGS...]"]
    for title, commands in GROUPS.items():
        lines += ["", f"{title}:"]
        lines += [f"  {name:<24}{summary}" for name, (_, summary) in commands.items()]
    lines += ["", "`python -m nbrdf_tools COMMAND --help` describes each."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0 if argv else 2
    command, rest = argv[0], argv[1:]
    if command not in COMMANDS:
        print(f"python -m nbrdf_tools: unknown command '{command}'\n\n{usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[command][0])
    sys.argv = [f"python -m nbrdf_tools {command}", *rest]
    return module.main(rest) or 0


if __name__ == "__main__":
    sys.exit(main())
