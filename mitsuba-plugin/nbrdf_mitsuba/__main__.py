"""``python -m nbrdf_mitsuba COMMAND ...``: the package's commands.

    render        render a scene with the nbrdf/merl BSDFs (see nbrdf_mitsuba.render)
    import-keras  convert the authors' Keras NBRDFs (see nbrdf_mitsuba.import_keras)
    tabulate-rgl  tabulate an RGL measured BSDF (see nbrdf_mitsuba.tabulate_rgl)
    distill       train a neural BRDF from any Mitsuba BSDF (see nbrdf_mitsuba.distill)
    llvm          which libLLVM Dr.Jit uses (see nbrdf_mitsuba.llvm)
"""

from __future__ import annotations

import importlib
import sys

COMMANDS = {
    "render": ("nbrdf_mitsuba.render", "render a Mitsuba scene with the nbrdf and merl BSDFs"),
    "import-keras": ("nbrdf_mitsuba.import_keras", "convert the authors' Keras NBRDFs (.h5) to *.nbrdf.json"),
    "tabulate-rgl": ("nbrdf_mitsuba.tabulate_rgl", "tabulate an RGL measured BSDF (.bsdf) onto the MERL grid"),
    "distill": ("nbrdf_mitsuba.distill", "train a neural BRDF from any Mitsuba 3 BSDF (.xml, .json, .bsdf)"),
    "llvm": ("nbrdf_mitsuba.llvm", "report which libLLVM Dr.Jit's LLVM backend uses"),
}


def usage() -> str:
    lines = ["usage: python -m nbrdf_mitsuba COMMAND [ARGS...]", "", "commands:"]
    lines += [f"  {name:<14}{summary}" for name, (_, summary) in COMMANDS.items()]
    lines += ["", "`python -m nbrdf_mitsuba COMMAND --help` describes each."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0 if argv else 2
    if argv[0] == "--version":
        from importlib.metadata import PackageNotFoundError, version

        try:
            print(f"nbrdf-mitsuba {version('nbrdf-mitsuba')}")
        except PackageNotFoundError:
            print("nbrdf-mitsuba (not installed)")
        return 0
    command, rest = argv[0], argv[1:]
    if command not in COMMANDS:
        print(f"python -m nbrdf_mitsuba: unknown command '{command}'\n\n{usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[command][0])
    sys.argv = [f"python -m nbrdf_mitsuba {command}", *rest]
    return module.main(rest) or 0


if __name__ == "__main__":
    sys.exit(main())
