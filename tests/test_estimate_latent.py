"""The Dr.Jit decoder twin (issue 33): ``nbrdf_mitsuba.latent.Decoder`` equals the Rust decoder
(``nbrdf ae decode``) to float32 precision, equals a float64 NumPy oracle written from
docs/design.md section 7, and its gradient with respect to the code equals central finite
differences in float64."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from nbrdf_tools.common.paths import default_cli

ROOT = Path(__file__).resolve().parent.parent
AE_FILE = ROOT / "nbrdf-core" / "data" / "models" / "autoencoder.json"


@pytest.fixture
def decoder(llvm_variant):
    from nbrdf_mitsuba.latent import Decoder

    return Decoder(AE_FILE)


def codes(decoder, n=4):
    """Training codes moved off the training set (the decoder's manifold between materials)."""
    rng = np.random.default_rng(33)
    picks = decoder.anchors[rng.choice(len(decoder.anchors), n, replace=False)]
    return (picks + 0.3 * rng.standard_normal(picks.shape)).astype(np.float32)


def oracle(code: np.ndarray) -> np.ndarray:
    """Float64 decoder from the file: tanh hidden layer, linear output, de-standardised and
    clamped to the training range (docs/design.md section 7)."""
    ae = json.loads(AE_FILE.read_text())
    x = np.asarray(code, dtype=np.float64)
    layers = ae["decoder"]["layers"]
    for k, layer in enumerate(layers):
        W = np.asarray(layer["weights"], dtype=np.float64).reshape(layer["inputs"], layer["outputs"])
        x = x @ W + np.asarray(layer["bias"], dtype=np.float64)
        if k < len(layers) - 1:
            x = np.tanh(x)
    w = x * np.asarray(ae["std"]) + np.asarray(ae["mean"])
    return np.clip(w, ae["min"], ae["max"])


def rust_decode(code: np.ndarray, tmp_path: Path) -> np.ndarray:
    cli = default_cli()
    if not cli.is_file():
        pytest.skip(f"the nbrdf command {cli} is not built (make setup)")
    code_file, out = tmp_path / "code.json", tmp_path / "decoded.nbrdf.json"
    code_file.write_text(json.dumps([float(c) for c in code]))
    subprocess.run([str(cli), "ae", "decode", str(code_file), "-o", str(out)], check=True, capture_output=True)
    net = json.loads(out.read_text())
    return np.concatenate([np.concatenate([np.ravel(layer["weights"]), layer["bias"]]) for layer in net["layers"]])


def test_decoder_equals_the_rust_decoder(decoder, tmp_path):
    for i, code in enumerate(codes(decoder)):
        ref = rust_decode(code, tmp_path)
        got = decoder.decode_numpy(code)
        assert got.shape == (675,)
        # float32 sums in another order: a few ulps of the largest weights.
        np.testing.assert_allclose(got, ref, rtol=2e-5, atol=2e-5 * np.abs(ref).max(), err_msg=f"code {i}")


def test_decoder_equals_the_float64_oracle(decoder):
    for code in codes(decoder):
        ref = oracle(code)
        np.testing.assert_allclose(decoder.decode_numpy(code), ref, rtol=1e-5, atol=1e-5 * np.abs(ref).max())


def test_gradient_equals_central_differences(decoder):
    Float64 = dr.llvm.ad.Float64
    projection = np.random.default_rng(5).standard_normal(675)

    def loss(code: np.ndarray) -> float:
        return float(np.dot(np.asarray(decoder.decode(Float64(code)).numpy()), projection))

    for code in codes(decoder, 2).astype(np.float64):
        c = Float64(code)
        dr.enable_grad(c)
        dr.backward(dr.sum(decoder.decode(c) * Float64(projection)))
        grad = np.asarray(dr.grad(c).numpy())
        h = 1e-6
        numeric = np.array([(loss(code + h * e) - loss(code - h * e)) / (2 * h) for e in np.eye(32)])
        assert np.abs(grad).max() > 0
        np.testing.assert_allclose(grad, numeric, rtol=1e-5, atol=1e-6 * np.abs(numeric).max())


def test_wrong_code_size_and_missing_file_are_errors(decoder, tmp_path):
    from nbrdf_mitsuba.latent import Decoder, LatentError

    # The installed package finds its bundled copy (the same file as the repository's).
    assert Decoder().path.read_bytes() == AE_FILE.read_bytes()
    with pytest.raises(LatentError, match="32 values, got 31"):
        decoder.decode(mi.Float(np.zeros(31, dtype=np.float32)))
    with pytest.raises(LatentError, match="does not exist"):
        Decoder(tmp_path / "none.json")
    (tmp_path / "other.json").write_text('{"format": "nbrdf"}')
    with pytest.raises(LatentError, match="not an NBRDF autoencoder"):
        Decoder(tmp_path / "other.json")
