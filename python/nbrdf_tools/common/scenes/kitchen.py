"""The 'Country Kitchen' scene with materials replaced by measured ones (docs/design.md section 10).

'Country Kitchen' by Jay-Artist (https://www.blendswap.com/blends/view/42851), Mitsuba version
by B. Bitterli (https://benedikt-bitterli.me/resources/), released under CC BY 3.0
(https://creativecommons.org/licenses/by/3.0/); converted to Mitsuba 3 with binary PLY meshes.
The scene itself is not part of this repository: it is read from
``../shared/scenes/kitchen/scene.xml``, from ``$NBRDF_KITCHEN``, or from a path you give.

``scenes/kitchen_materials.json`` names the BSDFs (by their ``id`` in scene.xml) that are
replaced and the test-set MERL material each one gets; everything else is left as it is. The
override rewrites the XML text in memory: each named top-level ``<bsdf id="...">`` element is
replaced by the new BSDF, wrapped in ``twosided`` where the original was (our BSDFs reflect on
the front side only), and the result is loaded with ``mi.load_string`` with the kitchen folder on
Mitsuba's file resolver path, so meshes and textures resolve as before.

    from nbrdf_tools.common.scenes.kitchen import load_kitchen
    scene = load_kitchen({"CupboardUnitsBSDF": {"type": "nbrdf", "filename": "yellow-paint.nbrdf.json"}},
                         resx=320, resy=180, spp=16)
"""

from __future__ import annotations

import contextlib
import json
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import mitsuba as mi

from nbrdf_tools.common.paths import SCENES, MissingDataError, shared_path
from nbrdf_tools.common.render import bsdf_xml

DESCRIPTION = SCENES / "kitchen_materials.json"
CREDIT = ("'Country Kitchen' by Jay-Artist (blendswap.com/blends/view/42851), Mitsuba version by "
          "B. Bitterli, CC BY 3.0 (creativecommons.org/licenses/by/3.0)")


def kitchen_path(path: str | Path | None = None) -> Path:
    """scene.xml of the kitchen: ``path`` (a file or its folder), else $NBRDF_KITCHEN, else
    ``../shared/scenes/kitchen/scene.xml`` next to the repository."""
    if path is None:
        path = os.environ.get("NBRDF_KITCHEN") or shared_path("scenes", "kitchen", "scene.xml")
    path = Path(path)
    if path.is_dir():
        path = path / "scene.xml"
    return path


def load_description(path: Path = DESCRIPTION) -> dict:
    """The override description: ``{"overrides": {bsdf_id: merl_material, ...}, ...}``."""
    return json.loads(Path(path).read_text())


def _named_bsdfs(root: ET.Element) -> dict[str, tuple[ET.Element, ET.Element]]:
    """{id: (parent, element)} of every BSDF with an id, at any depth (some are nested, e.g.
    inside a ``bumpmap``, and referenced by their own id)."""
    found = {}
    for parent in root.iter():
        for child in parent:
            if child.tag == "bsdf" and child.get("id"):
                found[child.get("id")] = (parent, child)
    return found


def bsdf_ids(xml_text: str) -> dict[str, str]:
    """{id: type} of the named BSDFs of a scene."""
    return {k: e.get("type") for k, (_, e) in _named_bsdfs(ET.fromstring(xml_text)).items()}


def override_xml(xml_text: str, bsdfs: dict[str, dict]) -> str:
    """The scene's XML with the BSDFs named by ``bsdfs`` (id -> BSDF dict) replaced in place;
    a replacement is wrapped in ``twosided`` when the original BSDF was."""
    root = ET.fromstring(xml_text)
    named = _named_bsdfs(root)
    missing = sorted(set(bsdfs) - set(named))
    if missing:
        raise KeyError(f"no <bsdf> with id {', '.join(missing)} in the kitchen scene "
                       f"(ids: {', '.join(sorted(named))})")
    for bsdf_id, bsdf in bsdfs.items():
        parent, original = named[bsdf_id]
        if original.get("type") == "twosided" and bsdf.get("type") != "twosided":
            text = (f'<bsdf type="twosided" id="{bsdf_id}">\n'
                    + bsdf_xml(bsdf, indent="    ") + "\n</bsdf>")
        else:
            text = bsdf_xml(bsdf, bsdf_id=bsdf_id)
        replacement = ET.fromstring(text)
        replacement.tail = original.tail
        index = list(parent).index(original)
        parent.remove(original)
        parent.insert(index, replacement)
    return ET.tostring(root, encoding="unicode")


@contextlib.contextmanager
def resolver_path(folder: Path):
    """Puts ``folder`` first on Mitsuba's file resolver path for the duration."""
    resolver = mi.file_resolver()
    saved = [str(p) for p in resolver]
    resolver.prepend(str(folder))
    try:
        yield
    finally:
        resolver.clear()
        for p in saved:
            resolver.append(p)


def load_kitchen(bsdfs: dict[str, dict] | None = None, scene: str | Path | None = None, **params):
    """Loads the kitchen with ``bsdfs`` (id -> BSDF dict) replaced; ``params`` are the scene's
    parameters (``spp``, ``resx``, ``resy``, ``max_depth``; values are converted to str)."""
    path = kitchen_path(scene)
    if not path.is_file():
        raise MissingDataError(f"kitchen scene {path} not found: pass its path, set NBRDF_KITCHEN, or set "
                               "NBRDF_SHARED to the shared data folder that holds scenes/kitchen")
    text = path.read_text()
    if bsdfs:
        text = override_xml(text, bsdfs)
    with resolver_path(path.parent):
        return mi.load_string(text, **{k: str(v) for k, v in params.items()})


def override_bsdfs(description: dict, materials: dict, strategy: str) -> dict[str, dict]:
    """id -> BSDF dict for one evaluation: ``strategy`` is ``table`` (the ``merl`` BSDF, the
    ground truth), ``table-phong`` (the same, Phong-sampled with the NBRDF's lobe) or an NBRDF
    sampling (``uniform``, ``cosine``, ``phong``). ``materials`` maps MERL names to
    :class:`materials.Material`."""
    result = {}
    for bsdf_id, name in description["overrides"].items():
        material = materials[name]
        if strategy == "table":
            result[bsdf_id] = material.table_bsdf()
        elif strategy == "table-phong":
            result[bsdf_id] = material.table_bsdf("phong" if material.has_phong else None)
        else:
            result[bsdf_id] = material.nbrdf(strategy)
    return result
