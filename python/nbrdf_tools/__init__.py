"""nbrdf_tools: the evaluation and report scripts of nbrdf as one importable package.

Modules: :mod:`~nbrdf_tools.paths` (where the repository, the shared data and the ``nbrdf`` CLI
are), :mod:`~nbrdf_tools.cli` (running the CLI), :mod:`~nbrdf_tools.render` (renders, masks,
EXR/PNG), :mod:`~nbrdf_tools.metrics` (image metrics), :mod:`~nbrdf_tools.network` (the NumPy
forward pass), :mod:`~nbrdf_tools.scenes` (Veach and kitchen), :mod:`~nbrdf_tools.materials`,
:mod:`~nbrdf_tools.ground_truth` (cached references), :mod:`~nbrdf_tools.analytic_fit` (GGX,
Blinn-Phong, ABC and SGD fits in log space). Scripts, each ``python -m nbrdf_tools.X``:
``demo``, ``convergence``, ``train_report``, ``latent_report``, ``compare_materials``,
``bench_rays``, ``fidelity_report``.

Modules that render import ``nbrdf_mitsuba`` before Mitsuba (it points Dr.Jit at a usable
libLLVM); the package itself imports neither.
"""
