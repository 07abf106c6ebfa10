"""Finds a libLLVM >= 16 for Dr.Jit's LLVM backend; see :mod:`nbrdf_mitsuba._llvm` for how and
when Dr.Jit reads ``DRJIT_LIBLLVM_PATH``.

    python -m nbrdf_mitsuba.llvm            # what was found and what Dr.Jit loaded
    python -m nbrdf_mitsuba.llvm --quiet    # exit status 1 (and the fix) when unusable

The module state (``status``, ``chosen``) is read live from the implementation module.
"""

import sys

from . import _llvm
from ._llvm import (ENV, INSTRUCTION, MIN_MAJOR, SEARCH_PATTERNS, backend_version, candidates, check_backend,
                    configure, describe, find_libllvm, main, parse_version, problem)

__all__ = ["ENV", "INSTRUCTION", "MIN_MAJOR", "SEARCH_PATTERNS", "backend_version", "candidates", "check_backend",
           "configure", "describe", "find_libllvm", "main", "parse_version", "problem", "status", "chosen"]  # noqa: F822 (module __getattr__)


def __getattr__(name):
    return getattr(_llvm, name)


if __name__ == "__main__":
    sys.exit(_llvm.main())
