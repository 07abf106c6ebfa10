"""One material's conversion, as a worker runs it: train the network on its source, fit its
sampling, measure it against the source and draw its thumbnail.

The worker writes nothing where the library lives: it trains in a scratch folder of its own and
returns the network and the thumbnail as bytes with the row, and the process that runs the
library writes them (atomically). So a worker may sit on another machine, and a worker killed
midway leaves nothing half-written in the library.

Workers import ``nbrdf_mitsuba`` themselves before anything of Mitsuba (it registers the
``nbrdf`` and ``merl`` plugins, which a fresh worker process does not have).
"""

from __future__ import annotations

import fcntl
import io
import json
import os
import pty
import re
import resource
import signal
import struct
import subprocess
import sys
import tempfile
import termios
import time
import traceback
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nbrdf_tools.common import cli
from nbrdf_tools.library.sources import Source

# The metric names of nbrdf_tools.common.metrics and nbrdf_tools.common.compare_materials; lower is better
# for all but SSIM.
METRICS = ("rmse_tonemapped", "ssim", "flip_hdr", "log_error_adaptive", "log_error_uniform")
HIGHER_IS_BETTER = {"ssim"}
# Anisotropic networks: the sphere images are also rendered with the tangent frame turned, as
# nbrdf_tools.pages.fidelity does, so that the metrics see the anisotropy.
FRAME_TURNS_DEG = (0.0, 45.0, 90.0)
# The light of the thumbnail, an index into compare_materials.LIGHT_THETAS_DEG (30 degrees).
THUMBNAIL_LIGHT = 1
PROGRESS_TOPIC = "nbrdf-library"
# Options of `nbrdf train` the distiller spells differently.
DISTILL_OPTIONS = {"--lr": "--learning-rate"}


@dataclass(frozen=True)
class Settings:
    """What a worker needs besides the source; ``threads`` (trainer threads) is not part of the
    key, since the trainer's results do not depend on it."""
    cli: str
    train_args: tuple[str, ...] = ()
    fit_args: tuple[str, ...] = ()
    resolution: int = 128
    metric_samples: int = 100_000
    threads: int | None = None
    progress: bool = True


# ---------------------------------------------------------------------------------------------
# Progress from inside a worker: a local pool hands its processes a queue (set_queue); a Dask
# worker sends structured events to the client (Worker.log_event), which subscribes to them.

_queue = None


def set_queue(queue) -> None:
    global _queue
    _queue = queue


def import_plugin() -> None:
    """Registers the nbrdf and merl plugins in this process (and points Dr.Jit at a libLLVM)."""
    import nbrdf_mitsuba  # noqa: F401


def init_local_worker(queue) -> None:
    """The initializer of a local pool's processes."""
    set_queue(queue)
    import_plugin()


def _reporter():
    if _queue is not None:
        return lambda event: _queue.put_nowait(event)
    try:
        from distributed import get_worker

        worker = get_worker()
    except (ImportError, ValueError):
        return None
    return lambda event: worker.log_event(PROGRESS_TOPIC, event)


# ---------------------------------------------------------------------------------------------
# Commands


def _parent_death_signal():
    """Linux's prctl, looked up here: the child between fork and exec only calls it (no loading,
    no locks, which other threads of a Dask worker might hold)."""
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


_PRCTL = _parent_death_signal()


def _die_with_parent() -> None:
    """In a command's process before it starts: end it when the worker that started it ends,
    so that an aborted run leaves no trainer running on."""
    if _PRCTL is not None:
        _PRCTL(1, int(signal.SIGTERM))  # PR_SET_PDEATHSIG


_EPOCH = re.compile(rb"(\d+)/(\d+) \[")
_ANSI = re.compile(rb"\x1b\[[0-9;?]*[A-Za-z]")


def error_message(stderr: str) -> str:
    """The lines of a command's messages that say what went wrong (``error: ...``), else its last."""
    lines = [line.strip() for line in re.split(r"[\r\n]+", stderr) if line.strip()]
    errors = [line for line in lines if "error" in line.lower()]
    return " ".join(errors[-3:] or lines[-1:]) or "(no message)"


def run_tracked(argv: list, on_epoch=None) -> None:
    """Runs a training command; with ``on_epoch`` its stderr is a pseudo-terminal (the trainers
    draw their epoch bars only on a terminal) whose ``epoch/max [`` counters are passed on as
    they change. Raises cli.CommandError on failure."""
    argv = [str(a) for a in argv]
    if on_epoch is None:
        cli.run(argv, stdin=subprocess.DEVNULL, preexec_fn=_die_with_parent)
        return
    master, slave = pty.openpty()
    # A sane width: a 0-column terminal truncates the bars.
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 160, 0, 0))
    try:
        proc = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=slave,
                                env={**os.environ, "TERM": "xterm"}, preexec_fn=_die_with_parent)
    finally:
        os.close(slave)
    chunks, last = [], None
    try:
        while True:
            try:
                data = os.read(master, 65536)
            except OSError:  # EIO: the command closed the terminal
                break
            if not data:
                break
            chunks.append(data)
            found = _EPOCH.findall(data)
            if found and found[-1] != last:
                last = found[-1]
                on_epoch(int(last[0]), int(last[1]))
        returncode = proc.wait()
    finally:
        os.close(master)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    if returncode != 0:
        text = _ANSI.sub(b"", b"".join(chunks)).decode("utf-8", "replace")
        raise cli.CommandError(argv, returncode, text)


def train_command(source: Source, network: Path, settings: Settings) -> list:
    """``nbrdf train`` for tables and measurements, the distiller for Mitsuba BSDFs."""
    args = list(settings.train_args)
    if settings.threads is not None and "--threads" not in args:
        args += ["--threads", str(settings.threads)]
    quiet = [] if settings.progress else ["--quiet"]
    if source.kind == "mitsuba":
        args = [DISTILL_OPTIONS.get(a, a) for a in args]
        return [sys.executable, "-m", "nbrdf_mitsuba.distill", source.path, "-o", network, "--name", source.name,
                *quiet, *args]
    return [settings.cli, "train", source.path, "-o", network, "--name", source.name, *quiet, *args]


# ---------------------------------------------------------------------------------------------
# Measuring


def reference_bsdf(source: Source):
    """The source as Mitsuba evaluates it: the ``merl`` table, the ``measured`` RGL data, or the
    Mitsuba BSDF the distiller read."""
    from nbrdf_tools.common import compare_materials as cm

    if source.kind != "mitsuba":
        return cm.load_bsdf(source.path)
    from nbrdf_mitsuba import distill

    cm.set_variant()
    try:
        return distill.load_bsdf(Path(source.path))[0]
    except distill.DistillError as error:
        raise ValueError(str(error)) from None


def measure(reference, network, resolution: int, samples: int, anisotropic: bool) -> tuple[dict, np.ndarray]:
    """The metrics of the network against the reference (sphere images under five lights, and
    each frame turn for an anisotropic network: the means; the log-space error over ``samples``
    adaptive and uniform directions) and the thumbnail's pair of linear images (2, H, W, 3)."""
    from nbrdf_tools.common import compare_materials as cm
    from nbrdf_tools.common import metrics

    turns = FRAME_TURNS_DEG if anisotropic else (0.0,)
    ref = np.concatenate([cm.render_spheres(reference, resolution, frame_turn_deg=t) for t in turns])
    net = np.concatenate([cm.render_spheres(network, resolution, frame_turn_deg=t) for t in turns])
    per_image = []
    for r, t in zip(ref, net):
        r = np.moveaxis(r.astype(np.float64), 0, -1)
        t = np.moveaxis(t.astype(np.float64), 0, -1)
        per_image.append({"rmse_tonemapped": metrics.rmse_tonemapped(r, t), "ssim": metrics.ssim(r, t),
                          "flip_hdr": metrics.flip_hdr(r, t)})
    values = {k: float(np.mean([p[k] for p in per_image])) for k in per_image[0]}
    for sampling in ("adaptive", "uniform"):
        values[f"log_error_{sampling}"] = cm.log_error(reference, network, sampling, samples, turned=anisotropic)
    pair = np.stack([np.moveaxis(ref[THUMBNAIL_LIGHT], 0, -1), np.moveaxis(net[THUMBNAIL_LIGHT], 0, -1)])
    return values, pair


def thumbnail_png(pair: np.ndarray) -> bytes:
    """The source's sphere beside the network's, tone-mapped (metrics.tone_map), as PNG bytes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.image

    from nbrdf_tools.common import metrics

    source, network = (metrics.tone_map(image) for image in pair)
    gap = np.ones((source.shape[0], max(2, source.shape[1] // 32), 3))
    image = (np.concatenate([source, gap, network], axis=1) * 255.0 + 0.5).astype(np.uint8)
    buffer = io.BytesIO()
    matplotlib.image.imsave(buffer, image, format="png")
    return buffer.getvalue()


def weight_count(network: dict) -> int:
    return int(sum(np.size(layer["weights"]) + np.size(layer["bias"]) for layer in network["layers"]))


# ---------------------------------------------------------------------------------------------
# The task


def convert(source: Source, settings: Settings, key: str) -> dict:
    """Converts one material; never raises for a bad source: a failure is a row with
    ``status = "failed"`` and its ``error``. The row carries the outputs as bytes
    (``files``: network, thumbnail)."""
    start = time.perf_counter()
    row = {"name": source.name, "kind": source.kind, "source": source.path, "key": key}
    report = _reporter() if settings.progress else None
    step = "train"
    try:
        import_plugin()
        from nbrdf_tools.common import compare_materials as cm

        with tempfile.TemporaryDirectory(prefix="nbrdf-library-") as scratch:
            network_path = Path(scratch) / f"{source.name}.nbrdf.json"
            on_epoch = None
            if report is not None:
                def on_epoch(epoch, epochs):
                    report({"name": source.name, "epoch": epoch, "epochs": epochs})
            run_tracked(train_command(source, network_path, settings), on_epoch)
            step = "fit-phong"
            fit = [settings.cli, "fit-phong", network_path, *settings.fit_args]
            if settings.threads is not None and "--threads" not in settings.fit_args:
                fit += ["--threads", settings.threads]
            cli.run(fit, stdin=subprocess.DEVNULL, preexec_fn=_die_with_parent)
            step = "measure"
            network_bytes = network_path.read_bytes()
            network = json.loads(network_bytes)
            reference = reference_bsdf(source)
            values, pair = measure(reference, cm.load_bsdf(network_path), settings.resolution,
                                   settings.metric_samples, bool(network["provenance"].get("anisotropic")))
        provenance = network["provenance"]
        sampling = network.get("sampling") or {}
        row.update(status="ok", error=None, metrics=values, training_seconds=provenance.get("seconds"),
                   epochs=provenance.get("epochs"), weights=weight_count(network),
                   anisotropic=bool(provenance.get("anisotropic")), default_sampling=sampling.get("default"),
                   files={"network": network_bytes, "thumbnail": thumbnail_png(pair)})
    except cli.CommandError as error:
        row.update(status="failed", error=f"{step}: {error_message(error.stderr)}")
    except Exception as error:  # noqa: BLE001 - one bad source must not stop the library
        detail = "".join(traceback.format_exception_only(type(error), error)).strip()
        row.update(status="failed", error=f"{step}: {detail}")
    row["wall_seconds"] = time.perf_counter() - start
    # Peaks so far in this worker process and in the largest command it ran (the trainer): the
    # memory a worker needs (docs/scale.md).
    row["worker_peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    row["commands_peak_mib"] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return row
