"""Material libraries at scale: one command converts every material of a library into a neural
BRDF with its fitted sampling, measures each against its own source, and shows the library at a
glance.

    python -m nbrdf_tools library SRC... -o OUT [--train-args "..."] [--only PATTERN] [--force]
        [--executor local|dask] [--jobs N] [--address tcp://HOST:8786] [--no-progress]

Modules: :mod:`~nbrdf_tools.library.sources` (which files are materials),
:mod:`~nbrdf_tools.library.task` (one material, as a worker runs it),
:mod:`~nbrdf_tools.library.store` (the output folder: keys, atomic writes),
:mod:`~nbrdf_tools.library.executors` (local process pool, Dask distributed),
:mod:`~nbrdf_tools.library.report` (index.json, index.csv, gallery.png, index.html),
:mod:`~nbrdf_tools.library.main` (the command). docs/scale.md has the cluster set-up and the
cost model.
"""
