"""nbrdf_tools: nbrdf's results pages, benchmarks, the library command and their shared helpers.

``python -m nbrdf_tools`` lists the commands and ``python -m nbrdf_tools COMMAND ...`` runs one.
Grouped by kind:

* :mod:`~nbrdf_tools.common`: shared helpers (paths, running the CLI, renders and EXR, image
  metrics, the NumPy network, scenes, test materials, cached references, analytic fits, the
  two-material comparison);
* :mod:`~nbrdf_tools.pages`: one generator per page of ``docs/results/``, named after it;
* :mod:`~nbrdf_tools.bench`: speed benchmarks (rays per second);
* :mod:`~nbrdf_tools.library`: whole material libraries into networks (a user command);
* :mod:`~nbrdf_tools.data`: makers of data the project ships or tests with (the pretrained
  models, spectral RGL files);
* :mod:`~nbrdf_tools.demo`: ``make demo``.

Modules that render import ``nbrdf_mitsuba`` before Mitsuba (it points Dr.Jit at a usable
libLLVM); the package itself imports neither.
"""
