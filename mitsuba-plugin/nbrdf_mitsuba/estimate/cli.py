"""``python -m nbrdf_mitsuba.estimate``'s command line (see :mod:`nbrdf_mitsuba.estimate`)."""

from __future__ import annotations

import argparse
import os
import sys
import traceback
from pathlib import Path

from .. import _exit
from .errors import EstimateError
from .estimator import estimate
from .analytic_start import ANALYTIC_MODELS
from .models import MODELS
from .plan import CODE_STRENGTHS, FALLBACK_CODE_STRENGTH, FALLBACK_PULL_STRENGTH, PULL_STRENGTHS

#: Set (to anything), an unexpected error's traceback is printed after its one-line message.
TRACEBACK_VARIABLE = "NBRDF_TRACEBACK"
#: Former names of flags, still accepted (with a note on stderr) but no longer listed by --help.
DEPRECATED_FLAGS = {"--prior-weight": "--pull-strength", "--code-prior": "--code-strength"}


class _Deprecated(argparse.Action):
    """A former flag name: stores into its new name's destination, with a note on stderr."""

    def __call__(self, parser, namespace, values, option_string=None):
        print(f"warning: {option_string} is deprecated: use {DEPRECATED_FLAGS[option_string]}", file=sys.stderr)
        setattr(namespace, self.dest, values)


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m nbrdf_mitsuba.estimate",
        description="Estimate a material from images of a known scene by differentiable rendering (prb): the BSDF "
                    "with the given id is replaced by the model, whose parameters are fitted to the images.")
    p.add_argument("scene", type=Path, help="the scene (Mitsuba 3 XML): object, sensors, emitters")
    p.add_argument("--images", type=Path, nargs="+", required=True,
                   help="one EXR (linear RGB) per sensor of the scene, in the scene's order")
    p.add_argument("--bsdf-id", required=True, help="the id of the BSDF to estimate")
    p.add_argument("-o", "--output", type=Path, required=True,
                   help="OUT.nbrdf.json (nbrdf models) or OUT.json (analytic models: a mi.load_dict dictionary)")
    p.add_argument("--model", choices=MODELS, default="nbrdf", help="what to fit (default: nbrdf, with the prior)")
    p.add_argument("--steps", type=int, default=200, help="optimisation steps, each rendering every view (default: 200)")
    p.add_argument("--spp", type=int, default=8, help="samples per pixel of each render (default: 8)")
    p.add_argument("--seed", type=int, default=0, help="random seed of the renders (default: 0)")
    p.add_argument("--max-depth", type=int, default=3, help="prb's path depth (default: 3, direct light and one "
                                                            "bounce)")
    p.add_argument("--pull-strength", type=float,
                   help="strength of the pull toward the decoded network's BRDF (default: chosen among "
                        f"{', '.join(map(str, PULL_STRENGTHS))} by the last training view, held out, which may "
                        f"choose the best of the {', '.join(ANALYTIC_MODELS)} fits instead, written as the "
                        f"network's base; the common start without the prior only where the albedo check rejects every "
                        f"network of the prior; {FALLBACK_PULL_STRENGTH} with one image). Given, nothing is held "
                        "out and no analytic model is fitted")
    p.add_argument("--code-strength", type=float,
                   help="strength of the Gaussian penalty keeping the latent code near the training codes (default: "
                        + (f"{CODE_STRENGTHS[0]}" if len(CODE_STRENGTHS) == 1 else
                           f"chosen among {', '.join(map(str, CODE_STRENGTHS))} together with the pull's strength, by "
                           "the same held-out view") + f"; {FALLBACK_CODE_STRENGTH} with one image or a fixed "
                        "--pull-strength)")
    for former, current in DEPRECATED_FLAGS.items():
        p.add_argument(former, dest=current[2:].replace("-", "_"), type=float, action=_Deprecated,
                       help=argparse.SUPPRESS)
    p.add_argument("--ae", type=Path, help="the autoencoder (default: the pretrained one)")
    p.add_argument("-D", dest="define", action="append", default=[], metavar="KEY=VALUE",
                   help="set a scene parameter ($KEY in the XML), as for rendering")
    p.add_argument("--threads", type=int,
                   help="Dr.Jit's worker threads (default: one per core). A seed gives the same result to float "
                        "rounding (the gradients' sums run in thread order); with --threads 1, bit for bit")
    p.add_argument("--variant", help="Mitsuba variant, an *_ad_rgb one (default: llvm_ad_rgb)")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        summary = estimate(args)
    except EstimateError as error:  # the input's (2), or the estimate's own failure (1)
        print(f"error: {error}", file=sys.stderr)
        return error.exit_status
    except KeyboardInterrupt:
        print("error: interrupted; nothing written", file=sys.stderr)
        return 130
    except Exception as error:  # a bug, not the input: one line and a hint, no traceback
        message = next(iter(str(error).strip().splitlines()), "")
        print(f"error: unexpected {type(error).__name__}{': ' + message if message else ''}", file=sys.stderr)
        print(f"hint: a bug in the estimate, not a problem of its input: please report it with the command "
              f"line ({TRACEBACK_VARIABLE}=1 prints the traceback)", file=sys.stderr)
        if os.environ.get(TRACEBACK_VARIABLE):
            traceback.print_exc()
        return _exit.FAILED
    print(f"wrote {summary['output']} ({summary['model']}): loss {summary['loss_first']:.4g} -> "
          f"{summary['loss_last']:.4g} in {summary['steps']} steps, {summary['seconds']:.1f} s")
    if summary.get("analytic"):
        print(f"the held-out view chose the {summary['analytic']['type']} fit: it is the material's \"base\", "
              "under a zero network (the nbrdf BSDF renders it as the fit itself)")
    return _exit.SUCCESS

