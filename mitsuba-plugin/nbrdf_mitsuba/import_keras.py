"""Converts the authors' Keras NBRDFs (``*.h5``) to the ``*.nbrdf.json`` format.

    python -m nbrdf_mitsuba.import_keras IN.h5 -o OUT.nbrdf.json
    python -m nbrdf_mitsuba.import_keras DIR -o OUTDIR          # every DIR/*.h5 -> OUTDIR/NAME.nbrdf.json

The Keras files hold a Sequential model Dense(6 -> h, relu) -> Dense(h -> h, relu) ->
Dense(h -> 3) -> Lambda(exp(x) - 1); the datasets ``dense_k/dense_k/kernel:0`` (inputs x
outputs, ``y = x W + b``) and ``dense_k/dense_k/bias:0`` for k = 1, 2, 3. The kernels are
written row-major as they are, which is the layout of the JSON format (docs/design.md section 4).
Weights are written as the exact decimal value of each float32, so a round trip is lossless.
Needs h5py (``pip install 'nbrdf-mitsuba[keras]'``). A missing or malformed input, or flags that
do not go together, exit with status 2; an output that cannot be written, 1.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from . import _exit

LAYERS = 3
INPUTS, OUTPUTS = 6, 3


class KerasImportError(ValueError):
    """A Keras file that is not an NBRDF of the expected layout."""


def _h5py():
    try:
        import h5py
    except ImportError:
        raise SystemExit(
            "nbrdf_mitsuba.import_keras needs h5py to read Keras files: "
            "pip install 'nbrdf-mitsuba[keras]' (or: pip install h5py)"
        ) from None
    return h5py


def read_keras(path: str | Path) -> tuple[list[tuple[np.ndarray, np.ndarray]], dict]:
    """The three (kernel, bias) pairs of a Keras NBRDF and its file attributes."""
    h5py = _h5py()
    path = Path(path)
    try:
        file = h5py.File(path, "r")
    except OSError as error:
        raise KerasImportError(f"{path}: cannot open as HDF5: {error}") from None
    with file:
        layers = []
        for k in range(1, LAYERS + 1):
            group = f"dense_{k}/dense_{k}"
            try:
                kernel = np.asarray(file[f"{group}/kernel:0"], dtype=np.float32)
                bias = np.asarray(file[f"{group}/bias:0"], dtype=np.float32)
            except KeyError:
                raise KerasImportError(f"{path}: missing dataset {group}/kernel:0 or {group}/bias:0 "
                                   "(not a Keras NBRDF)") from None
            layers.append((kernel, bias))
        attrs = {key: _attr(value) for key, value in file.attrs.items()}
    _check_shapes(path, layers)
    return layers, attrs


def _attr(value):
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return [_attr(v) for v in value.tolist()]
    if isinstance(value, np.generic):
        return value.item()
    return value


def _check_shapes(path: Path, layers) -> None:
    (w1, b1), (w2, b2), (w3, b3) = layers
    hidden = w1.shape[1] if w1.ndim == 2 else -1
    expected = [((INPUTS, hidden), (hidden,)), ((hidden, hidden), (hidden,)), ((hidden, OUTPUTS), (OUTPUTS,))]
    for k, ((w, b), (ws, bs)) in enumerate(zip(layers, expected), start=1):
        if w.shape != ws or b.shape != bs:
            raise KerasImportError(f"{path}: layer dense_{k} has kernel {w.shape} and bias {b.shape}, expected "
                               f"{ws} and {bs} for a 6 -> {hidden} -> {hidden} -> 3 NBRDF")
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
            raise KerasImportError(f"{path}: layer dense_{k} holds non-finite weights")


def _exact(values: np.ndarray) -> list[float]:
    # float32 -> float64 is exact, and JSON writes the shortest repr of the float64.
    return [float(v) for v in np.asarray(values, dtype=np.float32).reshape(-1)]


def to_document(path: str | Path, exponent: float | None = None, specular_weight: float | None = None) -> dict:
    """The ``*.nbrdf.json`` document of one Keras file."""
    path = Path(path)
    layers, attrs = read_keras(path)
    document = {
        "format": "nbrdf",
        "version": 1,
        "name": path.name.removesuffix(".h5"),
        "layers": [
            {"inputs": int(w.shape[0]), "outputs": int(w.shape[1]), "weights": _exact(w), "bias": _exact(b)}
            for w, b in layers
        ],
    }
    if exponent is not None or specular_weight is not None:
        if exponent is None or specular_weight is None:
            raise ValueError("give both --exponent and --specular-weight")
        document["sampling"] = {"model": "blinn-phong", "exponent": float(exponent),
                                "specular_weight": float(specular_weight), "source": "manual"}
    document["provenance"] = {
        "source_file": path.name,
        "method": "imported from Keras",
        "tool": "nbrdf_mitsuba.import_keras",
        "keras_version": attrs.get("keras_version"),
        "keras_backend": attrs.get("backend"),
    }
    return document


def convert(source: str | Path, target: str | Path, **sampling) -> Path:
    """Writes ``target`` (a ``*.nbrdf.json`` file) from the Keras file ``source``."""
    target = Path(target)
    document = to_document(source, **sampling)
    target.parent.mkdir(parents=True, exist_ok=True)
    target.write_text(json.dumps(document) + "\n", encoding="utf-8")
    return target


def convert_dir(source: str | Path, target: str | Path, progress: bool = True, **sampling) -> list[Path]:
    """Converts every ``source/*.h5`` to ``target/NAME.nbrdf.json``."""
    files = sorted(Path(source).glob("*.h5"))
    if not files:
        raise KerasImportError(f"{source}: no *.h5 files")
    iterator = files
    if progress:
        try:
            from tqdm import tqdm

            iterator = tqdm(files, desc="import", unit="file")
        except ImportError:
            pass
    return [convert(f, Path(target) / (f.name.removesuffix(".h5") + ".nbrdf.json"), **sampling) for f in iterator]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m nbrdf_mitsuba.import_keras",
        description="Convert Keras NBRDFs (*.h5, Sztrajman et al. 2021) to *.nbrdf.json.",
    )
    parser.add_argument("input", type=Path, help="a Keras .h5 file, or a directory of them")
    parser.add_argument("-o", "--output", type=Path, required=True,
                        help="output .nbrdf.json file (file input) or directory (directory input)")
    parser.add_argument("--exponent", type=float, help="Blinn-Phong sampling exponent to store")
    parser.add_argument("--specular-weight", type=float, help="Blinn-Phong specular weight to store")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    sampling = {"exponent": args.exponent, "specular_weight": args.specular_weight}
    try:
        if args.input.is_dir():
            if args.output.exists() and not args.output.is_dir():
                parser.error(f"{args.output} exists and is not a directory")
            written = convert_dir(args.input, args.output, progress=not args.quiet, **sampling)
            if not args.quiet:
                print(f"wrote {len(written)} networks to {args.output}")
        elif args.input.is_file():
            output = args.output / (args.input.name.removesuffix(".h5") + ".nbrdf.json") \
                if args.output.is_dir() else args.output
            convert(args.input, output, **sampling)
            if not args.quiet:
                print(f"wrote {output}")
        else:
            parser.error(f"{args.input}: no such file or directory")
    except (KerasImportError, ValueError) as error:  # the input, or flags that do not go together
        print(f"error: {error}", file=sys.stderr)
        return _exit.USAGE
    except OSError as error:  # writing the output (reading errors are KerasImportError)
        print(f"error: {error}", file=sys.stderr)
        return _exit.FAILED
    return _exit.SUCCESS


if __name__ == "__main__":
    sys.exit(main())
