"""The estimation report's ground truths, split once into a tuning set and a test set.

The **tuning set** is what the estimator's defaults, constants, candidate rules and schedules
were chosen on: a ``roughplastic``, the four shared RGL measurements and two MERL tables. The
**test set** is what the estimator is judged on, and nothing may be chosen on it: every MERL
material of the pretrained autoencoder's test split that the tuning set does not hold (the prior
never saw them), each through one published fit tabulated by ``nbrdf synth`` (SGD and ABC in
turn, in the split's alphabetical order), Mitsuba conductors with measured spectra at several
roughnesses, a ``roughplastic`` and a ``principled`` of other parameters, and any RGL measurement
given with ``--rgl`` (none is shared beyond the tuning set's four).

Each truth is rendered for its training images through one of the scene forms users write
(:data:`FORMS`, in turn over its set's order): the marked BSDF nested in its shape, inside a
``twosided``, or shared by two shapes; every training scene takes its field of view as a ``-D``
parameter. The forms give the same images (the second shape of ``shared`` lies inside the
sphere, where no ray reaches); what they exercise is the estimate's handling of the scene.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from nbrdf_tools.common.paths import default_cli, shared_dir

SETS = ("test", "tuning")
RGL = ("paper_white", "cc_iris_purple_gem", "cc_ibiza_sunset", "colodur_napoli_4f")
#: From the autoencoder's test split (its JSON's "split"): the prior never saw these materials.
MERL = ("green-metallic-paint", "red-specular-plastic")
#: A Mitsuba BSDF as ground truth (the "any Mitsuba BSDF" case, and the --quick one).
MITSUBA_TRUTH = {"type": "roughplastic", "alpha": 0.15,
                 "diffuse_reflectance": {"type": "rgb", "value": [0.6, 0.2, 0.1]}}
TUNING = ("mitsuba-roughplastic", *(f"rgl-{n}" for n in RGL), *(f"merl-{n}" for n in MERL))

#: (MERL material, published fit, kind): the autoencoder's test split less the tuning set's two.
TEST_MERL = (
    ("aluminium", "sgd", "metallic"), ("black-oxidized-steel", "abc", "metallic"),
    ("blue-metallic-paint", "sgd", "metallic paint"), ("chrome", "abc", "metallic"),
    ("color-changing-paint3", "sgd", "metallic paint"), ("fruitwood-241", "abc", "diffuse (wood)"),
    ("gray-plastic", "sgd", "plastic"), ("light-brown-fabric", "abc", "fabric"),
    ("nickel", "sgd", "metallic"), ("pink-fabric", "abc", "fabric"),
    ("polyethylene", "sgd", "plastic"), ("red-fabric", "abc", "fabric"),
    ("special-walnut-224", "sgd", "diffuse (wood)"), ("specular-orange-phenolic", "abc", "plastic"),
    ("ss440", "sgd", "metallic"), ("two-layer-silver", "abc", "metallic"),
    ("white-fabric", "sgd", "fabric"), ("yellow-paint", "abc", "glossy paint"),
)
#: Conductors with measured spectra (Mitsuba's ``material``) at GGX alphas from mirror-like to rough.
TEST_CONDUCTORS = (("Au", 0.1), ("Cu", 0.25), ("Al", 0.05), ("Ag", 0.2), ("Cr", 0.35))
TEST_MITSUBA = {
    **{f"mitsuba-roughconductor-{metal}-{alpha:g}": {"type": "roughconductor", "material": metal, "alpha": alpha}
       for metal, alpha in TEST_CONDUCTORS},
    "mitsuba-roughplastic-blue": {"type": "roughplastic", "alpha": 0.3, "int_ior": 1.6,
                                  "diffuse_reflectance": {"type": "rgb", "value": [0.1, 0.25, 0.6]}},
    "mitsuba-principled-green": {"type": "principled", "roughness": 0.45, "metallic": 0.3, "specular": 0.6,
                                 "base_color": {"type": "rgb", "value": [0.2, 0.5, 0.25]}},
}
#: Where the marked BSDF sits in a training scene, in turn over a set's truths.
FORMS = ("nested", "twosided", "shared")


def merl_name(material: str, fit: str) -> str:
    return f"merl-{material}-{fit}"


def rgl_name(path: Path) -> str:
    stem = path.name.removesuffix(".bsdf")
    return f"rgl-{stem.removesuffix('_rgb')}"


def heldout_names(rgl_files: list[Path] = ()) -> list[str]:
    """The test set in its order: the Mitsuba truths, the MERL tables, then the ``--rgl`` files."""
    return [*TEST_MITSUBA, *(merl_name(m, fit) for m, fit, _ in TEST_MERL), *(rgl_name(p) for p in rgl_files)]


def names(which: str, rgl_files: list[Path] = ()) -> list[str]:
    """The truths of ``which`` (``test``, ``tuning`` or ``all``: the test set first)."""
    if which not in (*SETS, "all"):
        raise SystemExit(f"unknown set {which!r} (these are: test, tuning, all)")
    return [*(heldout_names(rgl_files) if which != "tuning" else []), *(TUNING if which != "test" else [])]


def set_of(name: str) -> str:
    """A truth's set: the tuning set's seven by name, every other truth (an ``--rgl`` file too) the test set."""
    return "tuning" if name in TUNING else "test"


def form_of(name: str, rgl_files: list[Path] = ()) -> str:
    """The scene form ``name``'s training images are rendered through: :data:`FORMS` in turn over its set."""
    order = list(TUNING) if set_of(name) == "tuning" else heldout_names(rgl_files)
    return FORMS[order.index(name) % len(FORMS)] if name in order else FORMS[0]


def kind_of(name: str) -> str:
    """What a truth is, in a word or two (the results page's test table)."""
    if name in TEST_MITSUBA or name == "mitsuba-roughplastic":
        spec = TEST_MITSUBA.get(name, MITSUBA_TRUTH)
        return f"Mitsuba {spec['type']}" + (f", {spec['material']}" if "material" in spec else "")
    for material, fit, kind in TEST_MERL:
        if name == merl_name(material, fit):
            return f"MERL {fit.upper()}, {kind}"
    return "MERL SGD" if name.startswith("merl-") else "RGL measured" if name.startswith("rgl-") else "-"


def check_rgl_files(rgl_files: list[Path]) -> None:
    """Refuses an ``--rgl`` file that is absent or one the tuning set holds."""
    for path in rgl_files:
        if not path.is_file():
            raise SystemExit(f"--rgl {path}: no such file")
        if rgl_name(path) in TUNING:
            raise SystemExit(f"--rgl {path}: {rgl_name(path)} is in the tuning set, never in the test set")


def _xml_value(value) -> str:
    if isinstance(value, dict):
        return ", ".join(str(v) for v in value["value"])
    return str(value)


def dict_to_xml(spec: dict) -> str:
    """A ``<bsdf id="mat">`` element of a flat ``mi.load_dict`` dictionary (rgb, float, string)."""
    parts = []
    for key, value in spec.items():
        if key == "type":
            continue
        tag = "rgb" if isinstance(value, dict) else "string" if isinstance(value, str) else "float"
        parts.append(f'<{tag} name="{key}" value="{_xml_value(value)}"/>')
    return f'<bsdf type="{spec["type"]}" id="mat">{"".join(parts)}</bsdf>'


def file_bsdf(kind: str, path: Path) -> str:
    return f'<bsdf type="{kind}" id="mat"><string name="filename" value="{path}"/></bsdf>'


def _file_truth(kind: str, path: Path) -> dict:
    return {"xml": file_bsdf(kind, path), "dict": {"type": kind, "filename": str(path)}}


def _merl_table(work: Path, material: str, fit: str, file_name: str) -> Path:
    table = work / "tables" / file_name
    if not table.is_file():
        table.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run([str(default_cli()), "synth", "--model", fit, "--material", material, "-o", str(table)],
                       check=True, capture_output=True)
    return table


def truth(name: str, work: Path, rgl_files: list[Path] = ()) -> dict | None:
    """``name``'s truth: {"xml": its <bsdf id="mat"> element, "dict": its mi.load_dict dictionary,
    "set", "form"}; None where its file is absent (a shared RGL measurement). A MERL table is made
    under ``work/tables`` the first time."""
    found: dict | None
    if name == "mitsuba-roughplastic" or name in TEST_MITSUBA:
        spec = TEST_MITSUBA.get(name, MITSUBA_TRUTH)
        found = {"xml": dict_to_xml(spec), "dict": spec}
    elif name in (f"rgl-{n}" for n in RGL):
        path = shared_dir() / "data" / "rgl" / f"{name.removeprefix('rgl-')}_rgb.bsdf"
        found = _file_truth("measured", path) if path.is_file() else None
        if found is None:
            print(f"skipping {name}: {path} is absent", file=sys.stderr)
    elif name in (f"merl-{n}" for n in MERL):
        material = name.removeprefix("merl-")
        found = _file_truth("merl", _merl_table(work, material, "sgd", f"{material}.binary"))
    elif name in {merl_name(m, fit) for m, fit, _ in TEST_MERL}:
        material, fit = next((m, fit) for m, fit, _ in TEST_MERL if merl_name(m, fit) == name)
        found = _file_truth("merl", _merl_table(work, material, fit, f"{material}-{fit}.binary"))
    else:
        path = next((p for p in rgl_files if rgl_name(p) == name), None)
        if path is None:
            raise SystemExit(f"unknown material: {name}")
        found = _file_truth("measured", path.resolve())
    return None if found is None else {**found, "set": set_of(name), "form": form_of(name, rgl_files)}
