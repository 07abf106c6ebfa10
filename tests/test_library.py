"""``python -m nbrdf_tools library``: a small library (a MERL table from ``nbrdf synth``, a
Mitsuba BSDF as load_dict JSON and as scene XML, a corrupt measurement) converted locally and on
a real Dask LocalCluster, with tiny training budgets.

* the corrupt source is a failed row with the trainer's message, the others are converted, the
  exit status is 1; a row's numbers agree with independent computations (the Rust tool's
  ``nbrdf compare`` for the log errors, a NumPy tone-mapped RMSE of the sphere images);
* the rerun trains nothing (the ``nbrdf`` invocations are logged by a wrapper); a changed
  source, setting, ``--force`` or ``--only`` redo exactly what they should;
* a run interrupted by Ctrl-C and then killed outright (the whole process group) ends, once
  rerun, with the uninterrupted run's numbers and no temporary file;
* the CSV and JSON indexes agree; the HTML page parses, with its sortable table;
* the Dask executor, with a cluster it starts and with ``--address`` of one started here, gives
  the local run's numbers (the trainer is deterministic per seed, whatever the thread count).
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import signal
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from nbrdf_tools.library import main as library_main
from nbrdf_tools.library import sources, store
from nbrdf_tools.library.task import error_message
from nbrdf_tools.common.paths import default_cli, shared_dir

CLI = default_cli()
needs_cli = pytest.mark.skipif(not CLI.is_file(), reason=f"the nbrdf CLI {CLI} is not built (make build)")
# Tiny budgets: the tests check the plumbing and the numbers' agreement, not the networks' quality.
FAST = ["--train-args", "--epochs 4 --samples 20000", "--fit-args", "--lobes 1 --samples 1000",
        "--resolution", "24", "--metric-samples", "2000"]
GOOD = ("diffuse", "plastic", "white")
PLASTIC_XML = """<bsdf version="3.0.0" type="roughplastic">
    <float name="alpha" value="0.3"/>
    <rgb name="diffuse_reflectance" value="0.2, 0.4, 0.6"/>
</bsdf>
"""


def library(*args, timeout: float = 300, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "nbrdf_tools.library", *map(str, args)], capture_output=True,
                          text=True, timeout=timeout, **kwargs)


def write_json_bsdf(path: Path, reflectance=(0.5, 0.3, 0.2)) -> Path:
    path.write_text(json.dumps({"type": "diffuse", "reflectance": {"type": "rgb", "value": list(reflectance)}}))
    return path


def index(out: Path) -> dict:
    return json.loads((out / "index.json").read_text())


def rows_by_name(out: Path) -> dict[str, dict]:
    return {row["name"]: row for row in index(out)["materials"]}


def temporaries(out: Path) -> list[Path]:
    return sorted(out.rglob(store.TEMP_PREFIX + "*"))


def counting_cli(folder: Path) -> tuple[Path, Path]:
    """A wrapper of the nbrdf CLI that logs each invocation's subcommand; (wrapper, log)."""
    log = folder / "nbrdf-calls.log"
    wrapper = folder / "nbrdf"
    wrapper.write_text(f'#!/bin/sh\necho "$1" >> "{log}"\nexec "{CLI.resolve()}" "$@"\n')
    wrapper.chmod(0o755)
    return wrapper, log


def slow_cli(folder: Path, seconds: float = 1.5) -> Path:
    """A wrapper of the nbrdf CLI that waits before each fit-phong (every material runs one), so
    that a run interrupted after its first material still has the others in flight."""
    wrapper = folder / "nbrdf-slow"
    wrapper.write_text(f'#!/bin/sh\n[ "$1" = fit-phong ] && sleep {seconds}\nexec "{CLI.resolve()}" "$@"\n')
    wrapper.chmod(0o755)
    return wrapper


@pytest.fixture(scope="module")
def sources_dir(tmp_path_factory) -> Path:
    if not CLI.is_file():
        pytest.skip(f"the nbrdf CLI {CLI} is not built (make build)")
    folder = tmp_path_factory.mktemp("library-sources")
    subprocess.run([CLI, "synth", "--model", "sgd", "--material", "white-diffuse-bball", "-o", folder / "white.binary"],
                   check=True, capture_output=True)
    write_json_bsdf(folder / "diffuse.json")
    (folder / "plastic.xml").write_text(PLASTIC_XML)
    (folder / "broken.bsdf").write_text("tensor_file? no: this measurement is corrupt\n")
    (folder / "notes.txt").write_text("not a source: ignored\n")
    return folder


@pytest.fixture(scope="module")
def converted(sources_dir, tmp_path_factory):
    """The library converted once with the local executor: (OUT, the completed process)."""
    out = tmp_path_factory.mktemp("library-out") / "lib"
    result = library(sources_dir, "-o", out, *FAST, "--no-progress")
    return out, result


# ---------------------------------------------------------------------------------------------
# Small parts


def test_sources_are_found_by_kind_and_name(tmp_path):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    for name in ("a/x.binary", "a/y.bsdf", "a/z.json", "a/w.xml", "a/net.nbrdf.json", "a/readme.md", "b/x.json"):
        (tmp_path / name).write_text("")
    (tmp_path / "odd.txt").write_text("")
    found, refused = sources.discover([tmp_path / "a", tmp_path / "b", tmp_path / "odd.txt"])
    assert {(s.name, s.kind) for s in found} == {("y", "rgl"), ("z", "mitsuba"), ("w", "mitsuba")}
    # Two sources named x: both refused (neither output may silently replace the other), and an
    # explicitly named file of no known kind.
    assert sorted((r.name, "2 sources are named x" in r.error) for r in refused) == [
        ("odd", False), ("x", True), ("x", True)]
    with pytest.raises(FileNotFoundError):
        sources.discover([tmp_path / "missing"])
    assert sources.select(["gold", "green", "red"], ["g*"]) == {"gold", "green"}


def test_threads_do_not_enter_the_key():
    assert library_main.without_threads(("--epochs", "3", "--threads", "2", "--threads=4", "--seed", "1")) == [
        "--epochs", "3", "--seed", "1"]


def test_atomic_write_leaves_the_old_file_or_the_new(tmp_path, monkeypatch):
    path = store.write_atomic(tmp_path / "f.json", "old")
    assert path.stat().st_mode & 0o777 == 0o666 & ~_umask()  # not mkstemp's private 0600

    def cut(*_):
        raise OSError("disk gone")

    monkeypatch.setattr(os, "replace", cut)
    with pytest.raises(OSError):
        store.write_atomic(path, "new")
    monkeypatch.undo()
    assert path.read_text() == "old" and temporaries(tmp_path) == []
    (tmp_path / "m").mkdir()
    (tmp_path / "m" / (store.TEMP_PREFIX + "abc")).write_text("half")
    assert store.remove_temporaries(tmp_path) == 1 and temporaries(tmp_path) == []


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def test_error_message_keeps_the_error_lines():
    assert error_message("epoch 1/4 [==]\r\nerror: x.bsdf: bad header\n") == "error: x.bsdf: bad header"
    assert error_message("Traceback\n  ...\nValueError: broken\n") == "ValueError: broken"


# ---------------------------------------------------------------------------------------------
# The library, local executor


@needs_cli
def test_library_converts_and_records_the_failure(converted, sources_dir):
    out, result = converted
    assert result.returncode == 1, result.stderr
    rows = rows_by_name(out)
    assert sorted(rows) == ["broken", *GOOD]
    broken = rows["broken"]
    assert broken["status"] == "failed" and broken["kind"] == "rgl"
    assert "broken.bsdf" in broken["error"] and broken["error"].startswith("train: error:"), broken["error"]
    assert "failed: broken: train: error:" in result.stderr
    for name in GOOD:
        row = rows[name]
        assert row["status"] == "ok", row
        network = json.loads((out / row["files"]["network"]).read_text())
        assert network["name"] == name and network["provenance"]["epochs"] == 4
        assert row["weights"] == 675 and row["epochs"] == 4 and row["training_seconds"] > 0
        # fit-phong ran: the network carries its sampling choice.
        assert network["sampling"]["default"] == row["default_sampling"]
        m = row["metrics"]
        assert 0 <= m["rmse_tonemapped"] < 0.3 and 0 < m["ssim"] <= 1 and 0 <= m["flip_hdr"] < 1
        assert 0 <= m["log_error_adaptive"] < 1 and 0 <= m["log_error_uniform"] < 1
        thumb = out / row["files"]["thumbnail"]
        assert thumb.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert rows["white"]["kind"] == "merl" and rows["plastic"]["kind"] == rows["diffuse"]["kind"] == "mitsuba"
    assert (out / "gallery.png").stat().st_size > 1000
    assert temporaries(out) == []
    assert not (out / "materials" / "notes").exists()


@needs_cli
def test_row_numbers_agree_with_independent_computations(converted, sources_dir):
    """The log errors against the Rust tool (`nbrdf compare`, its own evaluation of table and
    network on the same directions); the tone-mapped RMSE against NumPy on the sphere images."""
    import nbrdf_mitsuba  # noqa: F401
    from nbrdf_tools.common import compare_materials as cm

    out, _ = converted
    row = rows_by_name(out)["white"]
    network = out / row["files"]["network"]
    table = sources_dir / "white.binary"
    rust = json.loads(subprocess.run([CLI, "compare", table, network, "--json", "--resolution", "24", "--samples",
                                      "2000"], check=True, capture_output=True, text=True).stdout)
    rust = rust.get("comparison", rust)
    for sampling in ("adaptive", "uniform"):
        assert row["metrics"][f"log_error_{sampling}"] == pytest.approx(rust[f"log_error_{sampling}"], rel=2e-3)
    a = cm.render_spheres(cm.load_bsdf(table), 24).astype(np.float64)
    b = cm.render_spheres(cm.load_bsdf(network), 24).astype(np.float64)

    def display(x):
        return np.clip(np.maximum(x, 1e-12) ** (1 / 2.2), 0, 1)

    per_light = np.sqrt(np.mean((display(a) - display(b)) ** 2, axis=(1, 2, 3)))
    assert row["metrics"]["rmse_tonemapped"] == pytest.approx(per_light.mean(), rel=1e-9)


@needs_cli
def test_csv_and_json_agree(converted):
    out, _ = converted
    rows = rows_by_name(out)
    with open(out / "index.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert [r["name"] for r in table] == sorted(rows)
    for line in table:
        row = rows[line["name"]]
        assert line["status"] == row["status"] and line["kind"] == row["kind"]
        assert line["error"] == (row["error"] or "")
        for metric, value in (row.get("metrics") or {}).items():
            assert float(line[metric]) == value
        if row["status"] == "ok":
            assert float(line["training_seconds"]) == row["training_seconds"]
            assert int(line["weights"]) == row["weights"] and line["network"] == row["files"]["network"]
        else:
            assert line["rmse_tonemapped"] == "" and line["network"] == ""


class _Page(HTMLParser):
    def __init__(self):
        super().__init__()
        self.tags, self.columns, self.rows, self.images, self.script = [], [], 0, [], ""
        self._in_script = False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        self.tags.append((tag, attrs))
        if tag == "th" and "data-column" in attrs:
            self.columns.append(attrs["data-column"])
        if tag == "tr" and attrs.get("class"):
            self.rows += 1
        if tag == "img":
            self.images.append(attrs["src"])
        self._in_script = tag == "script"

    def handle_data(self, data):
        if self._in_script:
            self.script += data


@needs_cli
def test_html_page_parses_with_a_sortable_table(converted):
    out, _ = converted
    page = _Page()
    page.feed((out / "index.html").read_text())
    page.close()
    assert ("table", {"id": "materials"}) in page.tags
    assert {"name", "rmse_tonemapped", "ssim", "flip_hdr", "log_error_adaptive", "error"} <= set(page.columns)
    assert page.rows == 4 and len(page.images) == 3
    assert all((out / src).is_file() for src in page.images)  # relative: the page opens from disk
    assert "addEventListener" in page.script and "sort" in page.script


@needs_cli
def test_rerun_trains_nothing(converted, sources_dir, tmp_path):
    out, _ = converted
    before = {name: (out / "materials" / name / "row.json").read_bytes() for name in GOOD}
    wrapper, log = counting_cli(tmp_path)
    result = library(sources_dir, "-o", out, *FAST, "--no-progress", "--cli", wrapper)
    assert result.returncode == 1
    assert "0 converted, 3 up to date, 1 failed" in result.stdout
    # The corrupt source is tried again (a failure is never cached); nothing else ran.
    assert sorted(log.read_text().split()) == ["--version", "train"]
    assert {name: (out / "materials" / name / "row.json").read_bytes() for name in GOOD} == before
    log.unlink()
    result = library(sources_dir, "-o", out, *FAST, "--no-progress", "--cli", wrapper, "--force", "--only", "white")
    assert "1 converted, 0 up to date, 1 failed" in result.stdout
    assert sorted(log.read_text().split()) == ["--version", "fit-phong", "train"]


@needs_cli
def test_changed_source_or_setting_is_redone(tmp_path):
    src = tmp_path / "src"
    src.mkdir()
    write_json_bsdf(src / "a.json")
    out = tmp_path / "out"

    def run(*extra):
        result = library(src, "-o", out, *FAST, "--no-progress", *extra)
        assert result.returncode == 0, result.stderr
        return result.stdout

    assert "1 converted, 0 up to date" in run()
    first = rows_by_name(out)["a"]
    write_json_bsdf(src / "a.json", (0.9, 0.9, 0.9))  # a changed source
    assert "1 converted, 0 up to date" in run()
    second = rows_by_name(out)["a"]
    assert second["key"] != first["key"] and second["metrics"] != first["metrics"]
    assert "1 converted, 0 up to date" in run("--metric-samples", "1000")  # a changed setting
    # --threads alone is not a change (the trainer's results do not depend on it); --only leaves
    # the others as they are, and one never converted is listed as such.
    write_json_bsdf(src / "b.json")
    assert "0 converted, 1 up to date" in run("--metric-samples", "1000", "--only", "a", "--train-args",
                                              "--epochs 4 --samples 20000 --threads 1")
    rows = rows_by_name(out)
    assert rows["a"]["status"] == "ok" and rows["b"]["status"] == "pending"
    assert "--only" in rows["b"]["error"]


def network_content(out: Path, row: dict) -> dict:
    """A network file without its provenance (which records the training's seconds); the
    sampling's variances rounded (fit-phong sums them per thread: the last digits follow the
    thread count, and the library gives each task its share of the cores)."""
    network = json.loads((out / row["files"]["network"]).read_text())
    variances = network["sampling"].pop("relative_variance")
    network["sampling"]["relative_variance"] = {k: float(f"{v:.10e}") for k, v in variances.items()}
    return {k: v for k, v in network.items() if k != "provenance"}


@needs_cli
def test_interrupted_run_resumes_to_the_same_index(converted, sources_dir, tmp_path):
    """Ctrl-C after the first material, then a kill of the whole process group (a power cut)
    after the next, then a rerun: the numbers of the uninterrupted run, no temporary file."""
    reference = rows_by_name(converted[0])
    out = tmp_path / "lib"
    # The slow CLI: with the real one the last materials finished within tenths of a second of the
    # first (warm kernels, tiny budgets), and a Ctrl-C could land after the run had ended.
    argv = [sys.executable, "-m", "nbrdf_tools.library", sources_dir, "-o", out, *FAST, "--no-progress",
            "--cli", slow_cli(tmp_path)]

    def start():
        # SIGINT as a terminal's Ctrl-C finds it: a child inherits an ignored SIGINT across exec, and
        # Python then raises no KeyboardInterrupt (something earlier in the full suite ignores it).
        return subprocess.Popen([str(a) for a in argv], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))

    def wait_for_rows(count, proc, limit=240.0):
        deadline = time.monotonic() + limit
        while time.monotonic() < deadline:
            done = [p for p in (out / "materials").glob("*/row.json")
                    if json.loads(p.read_text())["status"] == "ok"] if (out / "materials").is_dir() else []
            if len(done) >= count:
                return
            assert proc.poll() is None, proc.communicate()
            time.sleep(0.02)
        raise AssertionError("no material finished in time")

    proc = start()
    wait_for_rows(1, proc)
    os.killpg(proc.pid, signal.SIGINT)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == library_main.EXIT_INTERRUPTED, stderr
    interrupted = rows_by_name(out)
    assert "pending" in {r["status"] for r in interrupted.values()}
    finished = sum(r["status"] == "ok" for r in interrupted.values())
    assert 1 <= finished < len(GOOD)

    proc = start()
    wait_for_rows(finished + 1, proc)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.communicate(timeout=60)
    # What a write cut short would leave behind.
    (out / "materials" / "white" / (store.TEMP_PREFIX + "cut")).parent.mkdir(parents=True, exist_ok=True)
    (out / "materials" / "white" / (store.TEMP_PREFIX + "cut")).write_text("half a network")

    result = library(sources_dir, "-o", out, *FAST, "--no-progress")
    assert result.returncode == 1, result.stderr
    assert temporaries(out) == []
    rows = rows_by_name(out)
    assert sorted(rows) == sorted(reference)
    for name, row in rows.items():
        assert row["status"] == reference[name]["status"]
        assert row.get("metrics") == reference[name].get("metrics")
        if row["status"] == "ok":
            assert network_content(out, row) == network_content(converted[0], reference[name]), name
    assert sorted(p.relative_to(out) for p in out.rglob("*")) == sorted(
        p.relative_to(converted[0]) for p in converted[0].rglob("*"))


# ---------------------------------------------------------------------------------------------
# Dask distributed


@needs_cli
def test_an_interrupt_just_after_a_row_is_stored_keeps_it_in_the_index(converted, sources_dir, tmp_path,
                                                                       monkeypatch):
    """The Ctrl-C that lands between storing a material and counting it: the index still says
    what the folder holds (in the full suite's timing this left a stored row listed as pending)."""
    stored = store.Store.put

    def put_then_interrupt(self, result):
        row = stored(self, result)
        raise KeyboardInterrupt(row["name"])

    monkeypatch.setattr(store.Store, "put", put_then_interrupt)
    out = tmp_path / "lib"
    code = library_main.main([str(sources_dir), "-o", str(out), *FAST, "--no-progress", "--only", "white"])
    assert code == library_main.EXIT_INTERRUPTED
    rows = rows_by_name(out)
    assert rows["white"]["status"] == "ok"
    assert rows["white"].get("metrics") == rows_by_name(converted[0])["white"].get("metrics")
    assert {rows[name]["status"] for name in GOOD if name != "white"} == {"pending"}


def _same_numbers(out: Path, reference_out: Path, names) -> None:
    rows, reference = rows_by_name(out), rows_by_name(reference_out)
    for name in names:
        assert rows[name]["status"] == "ok", rows[name]
        assert rows[name]["metrics"] == reference[name]["metrics"]
        assert network_content(out, rows[name]) == network_content(reference_out, reference[name])


@needs_cli
def test_dask_local_cluster(converted, sources_dir, tmp_path):
    """--executor dask without an address: a LocalCluster of two workers started and stopped by
    the command; the progress shows the workers' epochs (Dask structured events)."""
    src = tmp_path / "src"
    src.mkdir()
    for name in ("diffuse.json", "plastic.xml", "broken.bsdf"):
        shutil.copy(sources_dir / name, src / name)
    out = tmp_path / "lib"
    result = library(src, "-o", out, *FAST, "--executor", "dask", "--jobs", "2")
    assert result.returncode == 1, result.stderr
    assert rows_by_name(out)["broken"]["status"] == "failed"
    _same_numbers(out, converted[0], ("diffuse", "plastic"))
    assert "epoch 4/4" in result.stderr


@needs_cli
def test_dask_cluster_at_an_address(converted, sources_dir, tmp_path):
    from distributed import LocalCluster

    src = tmp_path / "src"
    src.mkdir()
    shutil.copy(sources_dir / "diffuse.json", src / "diffuse.json")
    out = tmp_path / "lib"
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster:
        result = library(src, "-o", out, *FAST, "--no-progress", "--executor", "dask", "--address",
                         cluster.scheduler_address)
        assert result.returncode == 0, result.stderr
        # The cluster outlives the command: it was not the command's to stop.
        assert cluster.status.name == "running"
    _same_numbers(out, converted[0], ("diffuse",))


def test_address_needs_dask(tmp_path):
    result = library(tmp_path, "-o", tmp_path / "out", "--address", "tcp://127.0.0.1:1")
    assert result.returncode == 2 and "--address needs --executor dask" in result.stderr


# ---------------------------------------------------------------------------------------------
# An RGL measurement (shared data)


@needs_cli
def test_rgl_measurement(tmp_path):
    measurement = shared_dir() / "data" / "rgl" / "paper_white_rgb.bsdf"
    if not measurement.is_file():
        pytest.skip(f"the shared RGL measurement {measurement} is absent (set NBRDF_SHARED)")
    out = tmp_path / "lib"
    result = library(measurement, "-o", out, *FAST, "--no-progress")
    assert result.returncode == 0, result.stderr
    row = rows_by_name(out)["paper_white_rgb"]
    assert row["kind"] == "rgl" and row["status"] == "ok"
    assert all(math.isfinite(v) for v in row["metrics"].values())
