"""``python -m nbrdf_mitsuba COMMAND ...``: the package's commands.

    render        render a scene with the nbrdf/merl BSDFs (see nbrdf_mitsuba.render)
    import-keras  convert the authors' Keras NBRDFs (see nbrdf_mitsuba.import_keras)
    tabulate-rgl  tabulate an RGL measured BSDF (see nbrdf_mitsuba.tabulate_rgl)
    distill       train a neural BRDF from any Mitsuba BSDF (see nbrdf_mitsuba.distill)
    estimate      estimate a material from images of a known scene (see nbrdf_mitsuba.estimate)
    llvm          which libLLVM Dr.Jit uses (see nbrdf_mitsuba.llvm)

Every command (also as ``python -m nbrdf_mitsuba.MODULE``) exits with one policy
(:mod:`nbrdf_mitsuba._exit`): 0 on success (``--help`` too); 2 for a usage or input error (a bad
flag, a missing or invalid file, an invalid value); 1 where the work itself failed (a render, a
training or an estimate that failed, a result that could not be written; ``llvm``: no usable
libLLVM). An error is one line on stderr, ``error: ...``, never a traceback.
"""

from __future__ import annotations

import importlib
import sys

from . import _exit

COMMANDS = {
    "render": ("nbrdf_mitsuba.render", "render a Mitsuba scene with the nbrdf and merl BSDFs"),
    "import-keras": ("nbrdf_mitsuba.import_keras", "convert the authors' Keras NBRDFs (.h5) to *.nbrdf.json"),
    "tabulate-rgl": ("nbrdf_mitsuba.tabulate_rgl", "tabulate an RGL measured BSDF (.bsdf) onto the MERL grid"),
    "distill": ("nbrdf_mitsuba.distill", "train a neural BRDF from any Mitsuba 3 BSDF (.xml, .json, .bsdf)"),
    "estimate": ("nbrdf_mitsuba.estimate", "estimate a material from images of a known scene (differentiable "
                                           "rendering)"),
    "llvm": ("nbrdf_mitsuba.llvm", "report which libLLVM Dr.Jit's LLVM backend uses"),
}


def usage() -> str:
    lines = ["usage: python -m nbrdf_mitsuba COMMAND [ARGS...]", "", "commands:"]
    lines += [f"  {name:<14}{summary}" for name, (_, summary) in COMMANDS.items()]
    lines += ["", "`python -m nbrdf_mitsuba COMMAND --help` describes each.",
              "Exit status: 0 done, 2 a usage or input error, 1 the work itself failed."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv and argv[0] in ("-h", "--help"):
        print(usage())
        return _exit.SUCCESS
    if not argv:
        print(f"{usage()}\n\nerror: no command given", file=sys.stderr)
        return _exit.USAGE
    if argv[0] == "--version":
        from importlib.metadata import PackageNotFoundError, version

        try:
            print(f"nbrdf-mitsuba {version('nbrdf-mitsuba')}")
        except PackageNotFoundError:
            print("nbrdf-mitsuba (not installed)")
        return _exit.SUCCESS
    command, rest = argv[0], argv[1:]
    if command not in COMMANDS:
        print(f"{usage()}\n\nerror: unknown command '{command}'", file=sys.stderr)
        return _exit.USAGE
    module = importlib.import_module(COMMANDS[command][0])
    sys.argv = [f"python -m nbrdf_mitsuba {command}", *rest]
    return module.main(rest) or _exit.SUCCESS


if __name__ == "__main__":
    sys.exit(main())
