"""Test materials and their cached artefacts: MERL-format tables, NBRDFs and Blinn-Phong fits.

* MERL materials: the table is synthesised from the published SGD fit (``nbrdf synth``); the
  NBRDF is trained on it with ``nbrdf train`` (the Rust trainer, the paper's recipe) when the CLI
  has the command, otherwise the authors' Keras network is imported from
  ``../shared/data/reference-nbrdf/merl/NAME.h5`` (trained on the real MERL measurement, not on
  our synthesised table: its error against the table is then not only the network's).
* RGL materials (a ``.bsdf`` file, or ``NAME`` for ``SHARED/data/rgl/NAME.bsdf``): the table is tabulated through Mitsuba's
  ``measured`` plugin (``python -m nbrdf_mitsuba.tabulate_rgl``; the ``merl`` representation);
  the NBRDF is trained on the measurement itself, ``nbrdf train NAME.bsdf`` (fallback:
  ``reference-nbrdf/rgl-isotropic/NAME.h5``).
* The Blinn-Phong sampling lobes are fitted to the NBRDF with ``nbrdf fit-phong``: the best
  single lobe (``--lobes 1``, kept in the record) and the two-lobe mixture (``--lobes 2``, stored
  in the network file, whose default sampling it becomes).

Every artefact lands under ``OUT/materials`` with a ``NAME.artefacts.json`` record of its inputs
(content hashes, commands); it is rebuilt when they change.

The test set: the MERL materials are split 80 % / 20 % by a fixed rule, every fifth material in
alphabetical order starting with the third (:data:`MERL_TEST_SET`); the autoencoder and
predictor of the latent-space work must not train on them.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

from nbrdf_tools.common import cli
from nbrdf_tools.common import network as nbrdf_network
from nbrdf_tools.common.ground_truth import file_hash
from nbrdf_tools.common.paths import MissingDataError, require_shared, shared_dir, shared_path

# The 100 MERL names in alphabetical order are `nbrdf list-materials`; the test set is
# names[2::5] (fixed here so that scripts need not run the CLI to know it).
MERL_TEST_SET = (
    "aluminium", "black-oxidized-steel", "blue-metallic-paint", "chrome", "color-changing-paint3",
    "fruitwood-241", "gray-plastic", "green-metallic-paint", "light-brown-fabric", "nickel",
    "pink-fabric", "polyethylene", "red-fabric", "red-specular-plastic", "special-walnut-224",
    "specular-orange-phenolic", "ss440", "two-layer-silver", "white-fabric", "yellow-paint",
)
# Default materials of the Veach evaluation: glossy test-set materials (metals, metallic paints,
# plastics, phenolic) and one fabric as a near-diffuse control.
VEACH_MERL = (
    "aluminium", "black-oxidized-steel", "blue-metallic-paint", "color-changing-paint3", "gray-plastic",
    "green-metallic-paint", "nickel", "red-specular-plastic", "pink-fabric",
)
VEACH_RGL = ("cc_ibiza_sunset_rgb", "cc_iris_purple_gem_rgb")
#: Revision of nbrdf-core's tabulated sampler: `nbrdf fit-phong` scores it to choose the file's
#: `sampling.default`, so cached fits are redone when it changes (2: 48 theta bins, views
#: normalised per band from its lower edge; 3: `t = (1 - cos theta_h)^(1/4)` bins and the
#: stored `sampling.table_cosine_weight`).
TABULATED_SAMPLER_REVISION = 3


def test_split(names: list[str]) -> list[str]:
    """The test split of a list of MERL names: every fifth in alphabetical order from the third."""
    return sorted(names)[2::5]


@dataclass
class Material:
    name: str
    kind: str  # "merl" or "rgl"
    table: Path  # MERL-format table (ground truth through the `merl` BSDF)
    network: Path  # *.nbrdf.json
    network_source: str  # "trained" (nbrdf train) or "keras" (imported reference network)
    measured: Path | None = None  # RGL .bsdf (ground truth through Mitsuba's `measured` BSDF)
    exponent: float | None = None  # the best single lobe
    specular_weight: float | None = None
    phong_source: str | None = None  # "fit" (nbrdf fit-phong) or None
    # The two-lobe mixture stored in the network file: [n1, n2], [w1, w2].
    two_lobe_exponents: tuple[float, float] | None = None
    two_lobe_weights: tuple[float, float] | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def has_phong(self) -> bool:
        return self.exponent is not None and self.specular_weight is not None

    @property
    def has_two_lobes(self) -> bool:
        return self.two_lobe_exponents is not None and self.two_lobe_weights is not None

    def nbrdf(self, sampling: str | None = None, **extra) -> dict:
        """The ``nbrdf`` BSDF; ``phong`` samples the best single lobe (not the first lobe of the
        file's two-lobe mixture) unless ``extra`` names another."""
        bsdf = {"type": "nbrdf", "filename": str(self.network)}
        if sampling is not None:
            bsdf["sampling"] = sampling
        if sampling == "phong" and self.has_phong:
            bsdf.update(exponent=float(self.exponent), specular_weight=float(self.specular_weight))
        bsdf.update(extra)
        return bsdf

    def table_bsdf(self, sampling: str | None = None) -> dict:
        """The ``merl`` BSDF of the table; ``phong`` uses the NBRDF's fitted lobe."""
        bsdf = {"type": "merl", "filename": str(self.table)}
        if sampling == "phong":
            bsdf.update(sampling="phong", exponent=float(self.exponent), specular_weight=float(self.specular_weight))
        elif sampling is not None:
            bsdf["sampling"] = sampling
        return bsdf

    def ground_truth_bsdf(self) -> dict:
        """The BSDF of the ground truth: the measured data for RGL materials, else the table
        (Phong-sampled when a lobe is known, which only changes its noise)."""
        if self.measured is not None:
            return {"type": "measured", "filename": str(self.measured)}
        return self.table_bsdf("phong" if self.has_phong else None)


def _run(command: list) -> str:
    return cli.run(command).stdout


class Artefacts:
    """Builds and caches tables, networks and Phong fits under ``out / "materials"``."""

    def __init__(self, out: Path, cli: Path, shared: Path | None = None, train_args: list[str] | None = None,
                 log=print):
        self.folder = Path(out) / "materials"  # made when the first material is built
        self.cli = Path(cli)
        self.shared = Path(shared) if shared is not None else shared_dir()
        self.train_args = list(train_args or [])
        self.log = log
        self._commands = None

    # -- what the CLI can do --------------------------------------------------------------------

    def commands(self) -> set[str]:
        if self._commands is None:
            self._commands = cli.commands(self.cli)
        return self._commands

    def can_train(self) -> bool:
        return "train" in self.commands()

    def can_fit_phong(self) -> bool:
        return "fit-phong" in self.commands()

    def predictor(self) -> Path | None:
        """The Phong-parameter predictor of the latent-space work, when it exists (CLI command
        ``predict-phong`` or ``predict``); None until then."""
        for name in ("predict-phong", "predict"):
            if name in self.commands():
                return self.cli
        return None

    # -- records ------------------------------------------------------------------------------

    def _record_path(self, name: str) -> Path:
        return self.folder / f"{name}.artefacts.json"

    def _record(self, name: str) -> dict:
        path = self._record_path(name)
        if path.is_file():
            try:
                return json.loads(path.read_text())
            except json.JSONDecodeError:
                return {}
        return {}

    def _save_record(self, name: str, record: dict) -> None:
        self._record_path(name).write_text(json.dumps(record, indent=2, sort_keys=True) + "\n")

    # -- building -----------------------------------------------------------------------------

    def _table_merl(self, name: str, record: dict) -> Path:
        table = self.folder / f"{name}.sgd.binary"
        inputs = {"command": "nbrdf synth --model sgd", "material": name}
        if not table.is_file() or record.get("table_inputs") != inputs or record.get("table_hash") != file_hash(table):
            self.log(f"  {name}: synthesising the table (nbrdf synth --model sgd)")
            _run([self.cli, "synth", "--model", "sgd", "--material", name, "-o", table])
            record.update(table_inputs=inputs, table_hash=file_hash(table))
        return table

    def _table_rgl(self, name: str, measured: Path, record: dict) -> Path:
        table = self.folder / f"{name}.binary"
        inputs = {"command": "python -m nbrdf_mitsuba.tabulate_rgl", "measured": file_hash(measured)}
        if not table.is_file() or record.get("table_inputs") != inputs or record.get("table_hash") != file_hash(table):
            self.log(f"  {name}: tabulating {measured.name} onto the MERL grid (nbrdf_mitsuba.tabulate_rgl)")
            _run([sys.executable, "-m", "nbrdf_mitsuba.tabulate_rgl", measured, "-o", table])
            record.update(table_inputs=inputs, table_hash=file_hash(table))
        return table

    def _network(self, name: str, data: Path, keras: Path, record: dict) -> tuple[Path, str]:
        """The NBRDF trained on ``data`` (a MERL-format table or an RGL measurement)."""
        network = self.folder / f"{name}.nbrdf.json"
        if self.can_train():
            inputs = {"source": "trained", "data": data.name, "data_hash": file_hash(data), "args": self.train_args}
        elif keras.is_file():
            inputs = {"source": "keras", "keras": file_hash(keras)}
        else:
            raise MissingDataError(f"{name}: the CLI {self.cli} cannot train (no `train` command) and "
                                   f"there is no reference network {keras}")
        # network_hash is the file as last written (after fit-phong stored its lobe in it).
        if network.is_file() and record.get("network_inputs") == inputs and record.get("network_hash") == file_hash(network):
            return network, inputs["source"]
        if inputs["source"] == "trained":
            self.log(f"  {name}: training the NBRDF (nbrdf train {data.name} {' '.join(self.train_args)})")
            _run([self.cli, "train", data, "-o", network, "--name", name, "--quiet", *self.train_args])
        else:
            self.log(f"  {name}: importing the authors' Keras NBRDF {keras}")
            from nbrdf_mitsuba import import_keras

            if import_keras.main([str(keras), "-o", str(network), "-q"]) != 0:
                raise RuntimeError(f"{name}: importing {keras} failed")
        record.update(network_inputs=inputs, network_hash=file_hash(network), network_trained_hash=file_hash(network))
        record.pop("phong_inputs", None)
        return network, inputs["source"]

    def _phong(self, name: str, network: Path, record: dict) -> None:
        if not self.can_fit_phong():
            return
        # "lobe" and "lobes" change the key whenever the choice of lobes changes, so older fits
        # are redone. The best single lobe (the phong strategies) is fitted into a scratch copy
        # and kept in the record; the two-lobe mixture is stored in the network file.
        inputs = {"command": "nbrdf fit-phong", "lobe": "variance", "lobes": [1, 2],
                  "network": record.get("network_trained_hash"), "tabulated_sampler": TABULATED_SAMPLER_REVISION}
        if record.get("phong_inputs") == inputs and record.get("network_hash") == file_hash(network):
            return
        self.log(f"  {name}: fitting the Blinn-Phong sampling lobes (nbrdf fit-phong --lobes 1, --lobes 2)")
        scratch = network.with_name(f"{name}.one-lobe.nbrdf.json")
        try:
            fit = json.loads(_run([self.cli, "fit-phong", network, "--json", "--lobe", "variance", "--lobes", "1",
                                   "-o", scratch]))
        finally:
            scratch.unlink(missing_ok=True)
        two = json.loads(_run([self.cli, "fit-phong", network, "--json", "--lobe", "variance", "--lobes", "2"]))
        # fit-phong rewrote the network file (with the lobes): remember what it now holds.
        record.update(phong_inputs=inputs, network_hash=file_hash(network),
                      phong_fit={k: fit[k] for k in ("exponent", "specular_weight", "loss", "model_exponent",
                                                 "model_specular_weight", "relative_variance") if k in fit},
                      two_lobe_fit={k: two[k] for k in ("two_lobe", "relative_variance") if k in two})

    def _material(self, name: str, kind: str, table: Path, keras: Path, measured: Path | None, record: dict) -> Material:
        network, source = self._network(name, measured or table, keras, record)
        self._phong(name, network, record)
        self._save_record(name, record)
        sampling = nbrdf_network.sampling_of(network)
        material = Material(name=name, kind=kind, table=table, network=network, network_source=source,
                            measured=measured)
        if sampling.get("model") == "blinn-phong":
            one = record.get("phong_fit") or sampling
            material.exponent = float(one["exponent"])
            material.specular_weight = float(one["specular_weight"])
            material.phong_source = sampling.get("source", "fit")
            second = sampling.get("second_lobe")
            if second:
                material.two_lobe_exponents = (float(sampling["exponent"]), float(second["exponent"]))
                material.two_lobe_weights = (float(sampling["specular_weight"]), float(second["specular_weight"]))
        if source == "keras":
            material.notes.append("NBRDF imported from the authors' Keras network (no `nbrdf train`)")
        if not material.has_phong:
            material.notes.append("no Blinn-Phong lobe (no `nbrdf fit-phong`): phong strategies skipped")
        return material

    def merl(self, name: str) -> Material:
        self.folder.mkdir(parents=True, exist_ok=True)
        record = self._record(name)
        table = self._table_merl(name, record)
        keras = self.shared / "data" / "reference-nbrdf" / "merl" / f"{name}.h5"
        return self._material(name, "merl", table, keras, None, record)

    def rgl_file(self, spec: str) -> Path:
        """The measurement of an RGL material given as a path to a ``.bsdf`` file or as a name in
        the shared data (``NAME`` -> ``SHARED/data/rgl/NAME.bsdf``)."""
        path = Path(spec)
        if path.suffix == ".bsdf" or path.is_file():
            return path
        return self.shared / "data" / "rgl" / f"{spec}.bsdf"

    def rgl(self, spec: str) -> Material:
        """An RGL material: ``spec`` is a ``.bsdf`` path or a name in the shared data."""
        measured = self.rgl_file(spec)
        if not measured.is_file():
            raise MissingDataError(f"RGL measurement {measured} is missing (give the path of a .bsdf file, or set "
                                   "NBRDF_SHARED to the shared data folder that holds data/rgl)")
        name = measured.name.removesuffix(".bsdf")
        self.folder.mkdir(parents=True, exist_ok=True)
        record = self._record(name)
        table = self._table_rgl(name, measured, record)
        keras = self.shared / "data" / "reference-nbrdf" / "rgl-isotropic" / f"{name}.h5"
        return self._material(name, "rgl", table, keras, measured, record)

    def is_rgl(self, spec: str) -> bool:
        return (spec.startswith("rgl:") or spec.endswith(".bsdf")
                or (self.shared / "data" / "rgl" / f"{spec}.bsdf").is_file())

    def get(self, spec: str) -> Material:
        """``NAME`` (MERL), ``rgl:NAME`` / ``NAME_rgb`` (RGL in the shared data) or ``PATH.bsdf``."""
        if self.is_rgl(spec):
            return self.rgl(spec.removeprefix("rgl:"))
        return self.merl(spec)

    def missing(self, specs: list[str]) -> list[str]:
        """What building ``specs`` would lack, checked before any work starts: the CLI, the RGL
        measurements and, when the CLI cannot train, the authors' networks (one line each)."""
        problems = []
        try:
            cli.check_cli(self.cli)
        except MissingDataError as error:
            return [str(error)]
        can_train = self.can_train()
        for spec in specs:
            if self.is_rgl(spec):
                measured = self.rgl_file(spec.removeprefix("rgl:"))
                if not measured.is_file():
                    problems.append(f"RGL measurement {measured} (give a .bsdf path or set NBRDF_SHARED)")
                    continue
                keras = self.shared / "data" / "reference-nbrdf" / "rgl-isotropic" / f"{measured.stem}.h5"
            else:
                keras = self.shared / "data" / "reference-nbrdf" / "merl" / f"{spec}.h5"
            if not can_train and not keras.is_file():
                problems.append(f"{spec}: the CLI cannot train and the reference network {keras} is missing")
        return problems


__all__ = ["MERL_TEST_SET", "VEACH_MERL", "VEACH_RGL", "Material", "Artefacts", "test_split"]


def authors_merl() -> Path:
    """The authors' Keras networks of the MERL materials, in the shared data."""
    return shared_path("data", "reference-nbrdf", "merl")


def train_missing(nbrdf: Path, out: Path, samples: int, source: str = "sgd", only: list[str] | None = None) -> None:
    """Trains `OUT/NAME.nbrdf.json` for every MERL material not yet there, with `nbrdf train`
    from the common initialisation (seed 0), then fits its sampling lobe.

    source "sgd": on the table synthesised from the material's SGD fit (runs anywhere).
    source "authors": on the tabulation of the authors' network of the material (trained by them
    on the real MERL measurement): the authors' networks are independently initialised, so
    re-learning them from the common initialisation gives aligned networks of the real
    materials (needs ../shared/data/reference-nbrdf/merl/).
    """
    names = json.loads(cli.run([nbrdf, "list-materials", "--json"]).stdout)
    if only is not None:
        names = [e for e in names if e["name"] in only]
    out.mkdir(parents=True, exist_ok=True)
    tables = out / "tables"
    tables.mkdir(exist_ok=True)
    if source == "authors":
        require_shared("data", "reference-nbrdf", "merl", what="--source authors: the authors' MERL networks")
        from nbrdf_mitsuba.import_keras import convert
    for k, entry in enumerate(names):
        name = entry["name"]
        net = out / f"{name}.nbrdf.json"
        if net.exists():
            continue
        table = tables / f"{name}.binary"
        start = time.perf_counter()
        if source == "sgd":
            cli.run([nbrdf, "synth", "--model", "sgd", "--material", name, "-o", table])
        else:
            keras = tables / f"{name}.authors.nbrdf.json"
            convert(authors_merl() / f"{name}.h5", keras)
            cli.run([nbrdf, "tabulate", keras, "-o", table])
            keras.unlink()
        cli.run([nbrdf, "train", table, "-o", net, "--samples", samples, "--name", name])
        cli.run([nbrdf, "fit-phong", net, "--lobes", "1"])  # one-lobe labels for the predictor
        table.unlink()  # 35 MB each; the source regenerates it
        print(f"[{k + 1}/{len(names)}] {name}: {time.perf_counter() - start:.1f} s", flush=True)
