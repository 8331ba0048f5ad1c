"""The files every command and the node's ``design_file`` take: a scene JSON or a COMPAS
Assembly JSON, told apart by the COMPAS ``dtype``, either gzipped when named ``*.gz``."""
from __future__ import annotations

from pathlib import Path

from ..analysis.assembly import Assembly
from ..scene import Scene, SceneError
from .compas import DEFAULT_DENSITY, compas_document, compas_scene, is_compas_assembly
from .scene_json import read_json, scene_from_dict
from .stored_interfaces import stored_assembly


def load_design(path, density: float | None = None, *, stored: bool = False, supports=None
                ) -> tuple[Scene, Assembly | None]:
    """The scene of the file at ``path`` and, with ``stored``, its assembly on the
    interfaces the file stores (a COMPAS file; else SceneError). ``density`` (kg/m^3): of
    the COMPAS blocks the file gives none (default 2500); a scene file gives every
    block's density or mass, so a density for it is an error. ``supports`` (node keys): the
    supports of a COMPAS file instead of its ``is_support`` flags (compas_cra's samples set
    theirs in scripts); a scene file flags its own."""
    doc, name = read_json(path)
    if is_compas_assembly(doc):
        doc, stem = compas_document(doc, name)
        scene = compas_scene(doc, stem, supports, default_density=density or DEFAULT_DENSITY)
        return scene, stored_assembly(scene, doc, stem) if stored else None
    if density is not None:
        raise SceneError(f"{name}: a density is for COMPAS files (their blocks have none); a "
                         "scene file gives each block's density or mass")
    if supports is not None:
        raise SceneError(f"{name}: supports by node key are for COMPAS files; a scene file "
                         "flags each support block (\"support\": true)")
    if stored:
        raise SceneError(f"{name}: a scene file stores no interfaces (--interfaces stored "
                         "needs a COMPAS Assembly file that has them)")
    return scene_from_dict(doc, Path(path).parent), None


__all__ = ["load_design"]
