"""The Keras importer: `python -m nbrdf_mitsuba.import_keras IN.h5|DIR -o OUT`."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from nbrdf_testing import keras_layers


def run(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "nbrdf_mitsuba.import_keras", *map(str, args)],
                          capture_output=True, text=True, timeout=120)


def test_file_to_file(shared, tmp_path):
    h5 = shared / "data" / "reference-nbrdf" / "merl" / "chrome.h5"
    out = tmp_path / "out" / "chrome.nbrdf.json"
    result = run(h5, "-o", out, "--exponent", "5000", "--specular-weight", "0.95")
    assert result.returncode == 0, result.stderr
    document = json.loads(out.read_text())
    assert document["name"] == "chrome"
    assert document["sampling"] == {"model": "blinn-phong", "exponent": 5000.0, "specular_weight": 0.95,
                                    "source": "manual"}
    assert document["provenance"]["source_file"] == "chrome.h5"
    assert document["provenance"]["method"] == "imported from Keras"
    assert [(l["inputs"], l["outputs"]) for l in document["layers"]] == [(6, 21), (21, 21), (21, 3)]
    (w1, _), _, _ = keras_layers(h5)
    np.testing.assert_array_equal(np.float32(document["layers"][0]["weights"]).reshape(6, 21), np.float32(w1))


def test_directory_to_directory(shared, tmp_path):
    source = tmp_path / "in"
    source.mkdir()
    for name in ("nylon", "teflon"):
        (source / f"{name}.h5").symlink_to(shared / "data" / "reference-nbrdf" / "merl" / f"{name}.h5")
    (source / "notes.txt").write_text("not a network")
    result = run(source, "-o", tmp_path / "out")
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["nylon.nbrdf.json", "teflon.nbrdf.json"]


def test_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.h5"
    bad.write_bytes(b"not hdf5 at all")
    result = run(bad, "-o", tmp_path / "bad.nbrdf.json")
    assert result.returncode == 2 and "bad.h5" in result.stderr
    result = run(tmp_path / "missing.h5", "-o", tmp_path / "x.json")
    assert result.returncode == 2 and "missing.h5" in result.stderr
    (tmp_path / "empty").mkdir()
    result = run(tmp_path / "empty", "-o", tmp_path / "out")
    assert result.returncode == 2 and "no *.h5 files" in result.stderr


def test_wrong_layout_is_rejected(tmp_path):
    import h5py

    path = tmp_path / "wide.h5"
    with h5py.File(path, "w") as f:
        for k, (i, o) in enumerate([(6, 8), (8, 9), (9, 3)], start=1):
            f[f"dense_{k}/dense_{k}/kernel:0"] = np.zeros((i, o), np.float32)
            f[f"dense_{k}/dense_{k}/bias:0"] = np.zeros(o, np.float32)
    result = run(path, "-o", tmp_path / "wide.nbrdf.json")
    assert result.returncode == 2 and "wide.h5" in result.stderr and "dense_2" in result.stderr
