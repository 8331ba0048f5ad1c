"""Interfaces as a COMPAS file stores them: checked as given (``--interfaces stored``), and
how our detection differs from them (``--interfaces compare``).

compas_assembly and compas_cra users analyse the interfaces stored in their files, found
with their own tolerances; a file exported from a model with imperfect geometry may only
stand on those. A stored interface becomes ours as it is: its polygon (counter-clockwise
about the normal), its frame (x axis, normal from the edge's first block into the second;
compas_cra's friction pyramid is aligned with that x axis) and its size as the area; no
vertex or width filter is applied.
"""
from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass

import numpy as np

from ..analysis.assembly import Assembly
from ..geometry.block import PosedBlock, pose_blocks
from ..geometry.contacts import Interface
from ..geometry.polygon import PlaneFrame, area_moments
from ..scene import Scene, SceneError
from .compas import CompasInterface, interfaces_of, node_keys

#: Matched pairs whose areas differ by more than this share are listed by the comparison.
AREA_TOLERANCE = 0.01


def stored_assembly(scene: Scene, doc: dict, stem: str) -> Assembly:
    """The assembly of ``scene`` (the document's own, :func:`rbe_ros.io.compas.compas_scene`)
    on the interfaces stored in the document, those between two supports left out."""
    blocks = tuple(pose_blocks(scene.blocks))
    index = {key: i for i, key in enumerate(node_keys(doc, stem))}
    out = []
    for it in interfaces_of(doc, stem):
        if it.a not in index or it.b not in index:
            raise SceneError(f"{stem}: an interface joins node {it.a} and node {it.b}, "
                             "which the assembly does not both have")
        a, b = index[it.a], index[it.b]
        if not (blocks[a].support and blocks[b].support):
            out.append(_ours(a, b, it, blocks, stem))
    Interface.compute_kerns(out)
    return Assembly(blocks, tuple(out), np.asarray(scene.gravity, dtype=float))


def _ours(a: int, b: int, it: CompasInterface, blocks: tuple[PosedBlock, ...],
          stem: str) -> Interface:
    where = f"{stem}: interface {it.a}-{it.b}"
    if len(it.points) < 3 or it.normal is None:
        raise SceneError(f"{where}: needs a polygon of at least 3 points and a frame")
    n, u = it.normal, it.xaxis - (it.xaxis @ it.normal) * it.normal
    if n @ (blocks[b].centroid - blocks[a].centroid) < 0:
        # compas_assembly's frame normal points out of the edge's first block; a file
        # that says otherwise gets the side its blocks say
        n = -n
    u = u / np.linalg.norm(u)
    frame = PlaneFrame(it.origin, u, np.cross(n, u), n)
    area = area_moments(frame.to_2d(it.points))[0]
    points = it.points if area > 0 else it.points[::-1]
    size = it.size if np.isfinite(it.size) and it.size > 0 else abs(area)
    return Interface(a, b, frame, points, float(size))


@dataclass(frozen=True)
class InterfaceComparison:
    """Detected interfaces against stored ones, by block pair (areas summed per pair)."""

    stored: int                                   # interfaces
    detected: int
    stored_area: float                            # m^2, all pairs
    detected_area: float
    missing: list[tuple[str, str, float]]         # stored pairs not detected: a, b, area
    extra: list[tuple[str, str, float]]           # detected pairs not stored
    area_changes: list[tuple[str, str, float, float]]   # a, b, stored, detected area;
                                                         # differing by > AREA_TOLERANCE

    def lines(self, limit: int = 10) -> list[str]:
        rel = (self.detected_area - self.stored_area) / self.stored_area \
            if self.stored_area else float("nan")
        out = [f"interfaces: {self.stored} stored, {self.detected} detected; area "
               f"{self.stored_area:.6g} m^2 stored, {self.detected_area:.6g} m^2 detected "
               f"({rel:+.2%})",
               f"  {len(self.missing)} stored pairs not detected, {len(self.extra)} detected "
               f"pairs not stored, {len(self.area_changes)} pairs whose area differs by more "
               f"than {AREA_TOLERANCE:.0%}"]
        for title, rows in (("missing", self.missing), ("extra", self.extra)):
            for a, b, area in rows[:limit]:
                out.append(f"  {title}: {a}|{b} area {area:.4g} m^2")
            if len(rows) > limit:
                out.append(f"  ... and {len(rows) - limit} more {title}")
        for a, b, s, d in self.area_changes[:limit]:
            out.append(f"  area: {a}|{b} stored {s:.4g} m^2, detected {d:.4g} m^2 "
                       f"({(d - s) / s:+.1%})")
        if len(self.area_changes) > limit:
            out.append(f"  ... and {len(self.area_changes) - limit} more area differences")
        return out

    def to_json(self) -> dict:
        return {"stored": self.stored, "detected": self.detected,
                "stored_area": self.stored_area, "detected_area": self.detected_area,
                "missing": [{"block_a": a, "block_b": b, "area": x} for a, b, x in self.missing],
                "extra": [{"block_a": a, "block_b": b, "area": x} for a, b, x in self.extra],
                "area_changes": [{"block_a": a, "block_b": b, "stored_area": s,
                                  "detected_area": d} for a, b, s, d in self.area_changes]}


def _pair_areas(assembly: Assembly) -> dict[tuple[str, str], float]:
    """Interface area by pair of block ids, the pairs in block order."""
    out: dict[tuple[int, int], float] = defaultdict(float)
    for it in assembly.interfaces:
        out[min(it.a, it.b), max(it.a, it.b)] += it.area
    ids = [b.id for b in assembly.blocks]
    return {(ids[a], ids[b]): out[a, b] for a, b in sorted(out)}


def compare_interfaces(detected: Assembly, stored: Assembly) -> InterfaceComparison:
    """How ``detected`` differs from ``stored`` (assemblies of the same blocks); pairs in
    block order, area differences largest first."""
    d, s = _pair_areas(detected), _pair_areas(stored)
    changes = [(a, b, s[a, b], d[a, b]) for a, b in s if (a, b) in d
               and abs(d[a, b] - s[a, b]) > AREA_TOLERANCE * s[a, b]]
    changes.sort(key=lambda r: -abs(r[3] - r[2]) / r[2])
    return InterfaceComparison(
        len(stored.interfaces), len(detected.interfaces), float(sum(s.values())),
        float(sum(d.values())), [(a, b, s[a, b]) for a, b in s if (a, b) not in d],
        [(a, b, d[a, b]) for a, b in d if (a, b) not in s], changes)


__all__ = ["AREA_TOLERANCE", "InterfaceComparison", "compare_interfaces", "stored_assembly"]
