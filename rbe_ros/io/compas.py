"""Read and write COMPAS Assembly JSON (compas_assembly / compas_cra), without COMPAS.

The format (compas 2; compas 1 files differ only in key names, which are mapped):
``{"dtype": ".../Assembly", "data": {"attributes": {...}, "graph": {"dtype": ...,
"data": {"default_node_attributes": {...}, "node": {key: {...}}, "edge": {u: {v: {...}}}}}}}``.
A node holds ``block`` (a mesh: ``vertex {id: {x, y, z}}``, ``face {id: [vertex ids]}`` wound
outward) and optionally ``is_support``; an edge holds ``interfaces``: each with ``points``,
``size``, ``frame {point, xaxis, yaxis}`` and ``forces`` (``c_np, c_nn, c_u, c_v`` per point).
Keys are strings of integers. The samples of compas_cra set their supports in scripts, not in
the files (bridge: nodes 0 and 1), except ``armadillo_cra.json``.
"""
from __future__ import annotations

import json
import os
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..analysis.assembly import Assembly
from ..geometry.repair import repair_block
from ..scene import Block, Scene, SceneError, make_block, make_scene, turned
from .scene_json import read_json

DEFAULT_DENSITY = 2500.0
SAMPLES_ENV = "RBE_COMPAS_SAMPLES"

# compas 1 -> compas 2 key names (as compas_cra's own compas_1to2.py maps them)
_OLD_KEYS = {"value": "data", "dna": "default_node_attributes", "dea": "default_edge_attributes",
             "dva": "default_vertex_attributes", "dfa": "default_face_attributes"}


@dataclass(frozen=True)
class CompasInterface:
    """An interface stored in a COMPAS assembly, between nodes ``a`` and ``b`` (keys)."""

    a: str
    b: str
    points: np.ndarray               # (k, 3) polygon, world
    size: float                      # area
    origin: np.ndarray | None        # frame point
    normal: np.ndarray | None        # xaxis x yaxis (unit)
    forces: np.ndarray | None        # (k, 4): c_np, c_nn, c_u, c_v
    xaxis: np.ndarray | None = None  # frame xaxis (unit)


def _modern(obj):
    """``obj`` with compas 1 key names mapped to compas 2 ones, recursively."""
    if isinstance(obj, dict):
        return {_OLD_KEYS.get(k, k): _modern(v) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_modern(v) for v in obj]
    return obj


def _unwrap(obj):
    """The payload of a typed COMPAS object ``{"dtype": ..., "data": ...}`` (else ``obj``)."""
    if isinstance(obj, dict) and "dtype" in obj and "data" in obj:
        return obj["data"]
    return obj


def is_compas_assembly(doc) -> bool:
    """Whether a JSON document is a COMPAS Assembly (by its ``dtype``)."""
    return isinstance(doc, dict) and str(doc.get("dtype", "")).endswith("Assembly")


def _stem(name: str) -> str:
    for suffix in (".gz", ".json"):
        name = name[:-len(suffix)] if name.endswith(suffix) else name
    return name


def compas_document(doc, name: str) -> tuple[dict, str]:
    """A parsed COMPAS Assembly document with compas 1 key names mapped, and the name of its
    file without suffixes (SceneError if it is not an Assembly): the input of
    :func:`compas_scene`, :func:`interfaces_of` and :func:`node_keys`."""
    doc = _modern(doc)
    if not is_compas_assembly(doc):
        dtype = str(doc.get("dtype", "")) if isinstance(doc, dict) else ""
        raise SceneError(f"{name}: not a COMPAS Assembly (dtype {dtype or 'missing'!r})")
    return doc, _stem(name)


def _read(path) -> tuple[dict, str]:
    return compas_document(*read_json(path, "COMPAS assembly"))


def _graph(doc: dict, where: str) -> dict:
    data = _unwrap(doc)
    graph = _unwrap(data.get("graph")) if isinstance(data, dict) else None
    if not isinstance(graph, dict) or not isinstance(graph.get("node"), dict):
        raise SceneError(f"{where}: the assembly has no graph with nodes")
    return graph


def _key_order(key: str):
    return (0, int(key), "") if key.lstrip("-").isdigit() else (1, 0, key)


def _nodes(graph: dict) -> list[tuple[str, dict]]:
    """(key, attributes with the graph's defaults filled in), keys in numeric order."""
    defaults = graph.get("default_node_attributes") or {}
    nodes = [(str(k), {**defaults, **(v or {})}) for k, v in graph["node"].items()]
    return sorted(nodes, key=lambda kv: _key_order(kv[0]))


def _mesh(block: dict, where: str) -> tuple[np.ndarray, list[list[int]]]:
    """Vertices (only those used by faces) and faces of a COMPAS mesh payload."""
    data = _unwrap(block)
    if not isinstance(data, dict) or "vertex" not in data or "face" not in data:
        raise SceneError(f"{where}: block has no mesh (vertex and face)")
    default = {"x": 0.0, "y": 0.0, "z": 0.0, **(data.get("default_vertex_attributes") or {})}
    raw_faces = data["face"].values() if isinstance(data["face"], dict) else data["face"]
    index: dict[str, int] = {}
    faces = []
    for f in raw_faces:
        face = []
        for v in f:
            key = str(v)
            if key not in index:
                index[key] = len(index)
            if not face or face[-1] != index[key]:
                face.append(index[key])
        if len(face) > 1 and face[0] == face[-1]:
            face.pop()
        if len(face) >= 3:
            faces.append(face)
    vertex = data["vertex"]
    if isinstance(vertex, list):
        vertex = {str(i): v for i, v in enumerate(vertex)}
    try:
        coords = []
        for key in index:
            v = vertex[key]
            if isinstance(v, dict):
                v = {**default, **v}
                coords.append((v["x"], v["y"], v["z"]))
            else:
                coords.append(tuple(v[:3]))
    except (KeyError, TypeError, IndexError):
        raise SceneError(f"{where}: a face names a vertex the block does not have") from None
    return np.asarray(coords, dtype=float).reshape(-1, 3), faces


def load_compas_assembly(path, supports=None, density: float | None = None,
                         default_density: float = DEFAULT_DENSITY) -> Scene:
    """A scene from a COMPAS Assembly JSON file (gzipped if its name ends in ``.gz``).

    Each block's frame has the world axes and its origin at the mean of the block's vertices
    (identity orientation, position that mean). Ids are the node keys, or a node's
    ``name`` attribute when it has one (files written by :func:`save_compas_assembly`).
    Supports are the nodes flagged ``is_support`` unless ``supports`` (node keys) is given,
    which replaces the flags. Density: ``density`` if given, else a node's ``density``
    attribute, else ``default_density`` (2500 kg/m^3).
    """
    return compas_scene(*_read(path), supports, density, default_density)


#: The axes compas_cra's examples/05_wedge.py turns its samples about (type-a..d, 90 deg).
EXAMPLE_AXES = {"y": (0.0, 1.0, 0.0), "x": (1.0, 0.0, 0.0), "xy30": (3.0 ** 0.5, 1.0, 0.0)}


def rotated_as_example(scene: Scene, axis, deg: float) -> Scene:
    """``scene`` turned as compas_cra's examples turn an assembly,
    ``assembly.rotate_assembly([0, 0, 0], axis, deg)``: about ``axis`` through the origin,
    gravity kept along -z."""
    axis = np.asarray(axis, dtype=float)
    return turned(scene, Rotation.from_rotvec(np.radians(deg) * axis / np.linalg.norm(axis)))


def compas_scene(doc: dict, stem: str, supports=None, density: float | None = None,
                 default_density: float = DEFAULT_DENSITY) -> Scene:
    """The scene of a document of :func:`compas_document` (see :func:`load_compas_assembly`)."""
    graph = _graph(doc, stem)
    nodes = _nodes(graph)
    keys = {k for k, _ in nodes}
    wanted = None if supports is None else {str(s) for s in supports}
    if wanted is not None and not wanted <= keys:
        raise SceneError(f"{stem}: support nodes {sorted(wanted - keys, key=_key_order)} are"
                         f" not in the assembly")
    if wanted is not None and wanted == keys:
        raise SceneError(f"{stem}: the supports {sorted(wanted, key=_key_order)} are every node"
                         f" of the assembly: no free block to check")
    if wanted is None and not any(attr.get("is_support") for _, attr in nodes):
        raise SceneError(f"{stem}: no node is flagged is_support: name the supports by node key"
                         f" (rbe-ros: --supports KEY[,KEY...]; compas_cra's samples set theirs"
                         f" in their scripts)")
    blocks: list[Block] = []
    warnings: list[str] = []
    for key, attr in nodes:
        name = attr.get("name")
        bid = str(name) if isinstance(name, str) and name else key
        if not attr.get("block"):
            raise SceneError(f"{stem}: node {key} has no block")
        vertices, faces = _mesh(attr["block"], f"{stem}: node {key}")
        rho = density or attr.get("density") or default_density
        support = bool(attr.get("is_support")) if wanted is None else key in wanted
        # block frame: world axes at the mean of its vertices, so that a measured pose (and
        # a declared rotation uncertainty) turns the block about itself, not the world origin
        origin = vertices.mean(axis=0)
        block, warning = repair_block(make_block(bid, vertices - origin, faces, origin,
                                                 density=float(rho), support=support))
        blocks.append(block)
        if warning:
            warnings.append(warning)
    attributes = _unwrap(doc).get("attributes") or {}
    name = attributes.get("name") if attributes.get("name") not in (None, "Assembly") else stem
    return make_scene(str(name), blocks, warnings=warnings)


def compas_interfaces(path) -> list[CompasInterface]:
    """The interfaces stored in a COMPAS Assembly JSON file (edges u -> v, in file order)."""
    return interfaces_of(*_read(path))


def interfaces_of(doc: dict, stem: str) -> list[CompasInterface]:
    """The interfaces stored in a document of :func:`compas_document` (edges u -> v, in file
    order)."""
    graph = _graph(doc, stem)
    defaults = graph.get("default_edge_attributes") or {}
    out = []
    for u, nbrs in (graph.get("edge") or {}).items():
        for v, attr in (nbrs or {}).items():
            attr = {**defaults, **(attr or {})}
            raw = attr.get("interfaces") or ([attr["interface"]] if attr.get("interface") else [])
            if not raw and attr.get("interface_points"):             # compas_assembly 1.x
                raw = [{"points": attr["interface_points"], "size": attr.get("interface_size"),
                        "frame": attr.get("interface_frame"),
                        "forces": attr.get("interface_forces")}]
            out.extend(_interface(str(u), str(v), _unwrap(it)) for it in raw)
    return out


def node_keys(doc: dict, stem: str) -> list[str]:
    """The node keys in the order of the scene's blocks (:func:`compas_scene`)."""
    return [k for k, _ in _nodes(_graph(doc, stem))]


def _interface(u: str, v: str, data: dict) -> CompasInterface:
    points = np.asarray([_unwrap(p)[:3] for p in data.get("points") or []],
                        dtype=float).reshape(-1, 3)
    frame = _unwrap(data.get("frame"))
    axes = None
    if isinstance(frame, dict) and frame.get("xaxis") is not None:
        axes = frame.get("point"), frame["xaxis"], frame["yaxis"]
    elif isinstance(frame, (list, tuple)) and len(frame) == 3:      # [point, xaxis, yaxis]
        axes = frame
    origin = normal = xaxis = None
    if axes is not None:
        origin, x, y = (np.asarray(_unwrap(a), dtype=float) for a in axes)
        n = np.cross(x, y)
        normal, xaxis = n / np.linalg.norm(n), x / np.linalg.norm(x)
    forces = data.get("forces")
    if forces:
        forces = np.array([[f.get(k, 0.0) for k in ("c_np", "c_nn", "c_u", "c_v")]
                           for f in forces], dtype=float)
    else:
        forces = None
    size = data.get("size")
    return CompasInterface(u, v, points, float(size) if size is not None else float("nan"),
                           origin, normal, forces, xaxis)


def save_compas_assembly(scene: Scene, path, *, interfaces: bool = True) -> None:
    """Write ``scene`` as a compas 2 Assembly JSON file (blocks in world coordinates).

    Nodes get integer keys in block order, with the block id as node ``name`` and
    ``is_support``; a node ``density`` or ``mass`` keeps the block's. With ``interfaces``,
    the detected interfaces go on the edges (``forces`` null).
    """
    assembly = Assembly.from_scene(scene)
    nodes, edges = {}, {str(i): {} for i in range(len(scene.blocks))}
    for i, (block, posed) in enumerate(zip(scene.blocks, assembly.blocks)):
        mesh = {
            "attributes": {"name": block.id, "node": i},
            "default_vertex_attributes": {"x": 0.0, "y": 0.0, "z": 0.0},
            "default_edge_attributes": {}, "default_face_attributes": {},
            "vertex": {str(k): dict(zip("xyz", map(float, p)))
                       for k, p in enumerate(posed.vertices)},
            "face": {str(k): [int(v) for v in f] for k, f in enumerate(block.faces)},
            "facedata": {}, "edgedata": {},
            "max_vertex": len(posed.vertices) - 1, "max_face": len(block.faces) - 1,
        }
        node = {"block": {"dtype": "compas_assembly.datastructures/Block", "data": mesh,
                          "guid": str(uuid.uuid5(uuid.NAMESPACE_URL,
                                                 f"rbe_ros/{scene.name}/{block.id}"))},
                "is_support": block.support, "name": block.id}
        node["density" if block.density > 0 else "mass"] = block.density or block.mass
        nodes[str(i)] = node
    if interfaces:
        for it in assembly.interfaces:
            frame = {"dtype": "compas.geometry/Frame",
                     "data": {"point": it.frame.origin.tolist(), "xaxis": it.frame.u.tolist(),
                              "yaxis": it.frame.v.tolist()}}
            data = {"points": it.points.tolist(), "size": float(it.area), "frame": frame,
                    "forces": None, "mesh": None}
            entry = edges[str(it.a)].setdefault(str(it.b), {"interfaces": []})
            entry["interfaces"].append({"dtype": "compas_assembly.datastructures/Interface",
                                        "data": data})
    adjacency = {str(i): {} for i in range(len(scene.blocks))}
    for u, nbrs in edges.items():
        for v in nbrs:
            adjacency[u][v] = None
            adjacency[v][u] = None
    graph = {"attributes": {"name": scene.name},
             "default_node_attributes": {"block": None, "is_support": False},
             "default_edge_attributes": {"interfaces": None},
             "node": nodes, "edge": edges, "adjacency": adjacency,
             "max_node": len(scene.blocks) - 1}
    doc = {"dtype": "compas_assembly.datastructures/Assembly",
           "data": {"attributes": {"name": scene.name},
                    "graph": {"dtype": "compas.datastructures/Graph", "data": graph}}}
    Path(path).write_text(json.dumps(doc, indent=1) + "\n")


def compas_samples_dir() -> Path | None:
    """compas_cra's sample folder: ``$RBE_COMPAS_SAMPLES``, else that of an importable
    compas_cra, else None."""
    env = os.environ.get(SAMPLES_ENV)
    if env:
        return Path(env) if Path(env).is_dir() else None
    try:
        import importlib.util
        spec = importlib.util.find_spec("compas_cra")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    folder = Path(list(spec.submodule_search_locations)[0]) / "data" / "samples"
    return folder if folder.is_dir() else None
