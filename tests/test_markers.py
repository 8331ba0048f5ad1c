"""The markers of reports (rbe_ros.io.markers): message dicts, checked against the report's own
numbers and the blocks' posed meshes; their CDR size for a 1000-block wall."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from helpers import stacked_boxes
from rbe_ros.io import cdr
from rbe_ros.analysis.pipeline import check_scene, check_sequence
from rbe_ros.io.bag import typestore
from rbe_ros.generators import running_bond_wall
from rbe_ros.geometry.block import pose_block
from rbe_ros.io.markers import (ADD, COMPRESSION, DELETEALL, INTERFACE_COLOURS, KERN, LINE_LIST,
                             MARKER_TYPE, ROLE_COLOURS, TENSION, TEXT_VIEW_FACING,
                             TRIANGLE_LIST, run_markers, step_markers)
from rbe_ros.io.messages import header_dict, report_to_dict, state_to_dict
from rbe_ros.io.replay import Run, replay_run
from rbe_ros.io.scene_json import load_scene
from rbe_ros.scene import Hold, box_block, make_scene

HEADER = header_dict("map", 7_000_000_008)


def _by(markers, ns):
    return [m for m in markers["markers"] if m["ns"] == ns]


def _colour(m):
    return tuple(m["color"][k] for k in "rgba")


def _segments(markers, ns="forces"):
    return {_colour(m): np.asarray(m["points"]).reshape(-1, 2, 3) for m in _by(markers, ns)}


@pytest.mark.parametrize("shift", [0.45, 0.55])
def test_markers_of_a_report(shift):
    scene = stacked_boxes(shift)
    report = check_scene(scene)
    markers = step_markers(scene, report, HEADER, max_length=0.5)
    first, *rest = markers["markers"]
    assert first["action"] == DELETEALL and all(m["action"] == ADD for m in rest)
    assert all(m["header"] == HEADER for m in markers["markers"])
    assert len({(m["ns"], m["id"]) for m in rest}) == len(rest)

    # every block a posed mesh in its role's colour; the tipping box red
    blocks = _by(markers, "blocks")
    assert [m["text"] for m in blocks] == ["ground", "a", "b"]
    for m in blocks:
        assert m["type"] == TRIANGLE_LIST
        world = pose_block(scene.block(m["text"])).vertices
        points = np.asarray(m["points"])
        assert len(points) == 36         # 6 faces, 2 triangles each
        assert np.abs(points[:, None, :] - world[None]).sum(axis=2).min(axis=1).max() < 1e-12
    roles = ["support", "stable", "unstable" if shift > 0.5 else "stable"]
    assert [_colour(m) for m in blocks] == [pytest.approx(ROLE_COLOURS[r]) for r in roles]

    # forces: a segment per interface vertex, from the vertex along the force, the largest
    # 0.5 m; tension red
    vertices = np.vstack([r.polygon for r in report.interfaces])
    forces = np.vstack([r.normal_forces[:, None] * r.normal + r.tangential_forces
                        for r in report.interfaces])
    normal = np.concatenate([r.normal_forces for r in report.interfaces])
    segments = _segments(markers)
    got = np.concatenate(list(segments.values()))
    assert len(got) == len(vertices) == 8
    order = [int(np.flatnonzero(np.all(got[:, 0] == v, axis=1))[0]) for v in vertices]
    scale = 0.5 / np.linalg.norm(forces, axis=1).max()
    assert np.allclose(got[order, 1], vertices + scale * forces)
    tension = segments.get(TENSION, np.empty((0, 2, 3)))
    expected_tension = vertices[normal < -1e-5 * np.abs(forces).max()]
    assert len(tension) == len(expected_tension) == (2 if shift > 0.5 else 0)
    assert set(map(tuple, segments)) <= {COMPRESSION, TENSION}

    # interfaces: closed outlines (red in tension); kerns blue and thinner
    outlines = np.concatenate([np.asarray(m["points"]) for m in _by(markers, "interfaces")])
    assert len(outlines) == 2 * len(vertices)
    kinds = {m["id"]: _colour(m) for m in _by(markers, "interfaces")}
    assert (2 in kinds) == (shift > 0.5) and kinds[0] == INTERFACE_COLOURS[0]
    [kerns] = _by(markers, "kerns")
    assert _colour(kerns) == KERN and kerns["type"] == LINE_LIST
    assert len(kerns["points"]) == 2 * sum(len(r.kern) for r in report.interfaces)

    # the caption: verdict and reason, above the assembly
    [text] = _by(markers, "text")
    assert text["type"] == TEXT_VIEW_FACING and text["text"].split("\n") == [
        report.status.name, report.message]
    assert text["pose"]["position"]["z"] > 2.0


def test_steps_of_a_sequence_placed_and_held():
    scene = load_scene("examples/build_sequence.json")
    scene = replace(scene, holds=(Hold("pillar_left", 2),))
    reports = check_sequence(scene)
    for report in reports:
        blocks = _by(step_markers(scene, report, HEADER), "blocks")
        ids = [m["text"] for m in blocks]
        assert len(ids) == report.num_blocks
        assert scene.sequence[report.step_index] in ids
        assert set(scene.sequence[report.step_index + 1:]).isdisjoint(ids)
        colour = {m["text"]: _colour(m) for m in blocks}
        assert colour[report.block_placed] == pytest.approx(
            ROLE_COLOURS["unstable" if report.block_placed in report.unstable_blocks
                         else "placed"])
        if report.step_index >= 2:
            assert colour["pillar_left"] == pytest.approx(ROLE_COLOURS["held"])


def test_invalid_input_highlights_the_blocks_at_fault():
    """Interpenetrating blocks: both drawn magenta, the reason as text; a state whose mesh
    cannot be read still shows its other blocks."""
    scene = make_scene("bad", [box_block("g", (3, 3, 0.2), (0, 0, -0.1), support=True,
                                               density=1000),
                               box_block("a", (1, 1, 1), (0, 0, 0.5), density=1000),
                               box_block("b", (1, 1, 1), (0.2, 0, 0.9), density=1000)])
    state = state_to_dict(scene, "w", 5)
    [report] = replay_run(Run(state, 5))
    assert report["status"] == 5 and "interpenetrate" in report["message"]
    [markers] = run_markers(state, [report])
    colour = {m["text"]: _colour(m) for m in _by(markers, "blocks")}
    assert colour == {"g": pytest.approx(ROLE_COLOURS["stable"]),
                      "a": pytest.approx(ROLE_COLOURS["fault"]),
                      "b": pytest.approx(ROLE_COLOURS["fault"])}
    assert _by(markers, "text")[0]["text"].endswith(report["message"])

    state["blocks"][2]["mesh"]["triangles"][0]["vertex_indices"] = [0, 1, 99]
    [report] = replay_run(Run(state, 5))
    assert report["status"] == 5 and "'b'" in report["message"]
    [markers] = run_markers(state, [report])
    colour = {m["text"]: _colour(m) for m in _by(markers, "blocks")}
    assert colour["b"] == pytest.approx(ROLE_COLOURS["fault"])
    assert colour["a"] == pytest.approx(ROLE_COLOURS["stable"])
    assert len(_by(markers, "blocks")[2]["points"]) == 33   # the bad triangle left out


def test_wall_of_1000_blocks_aggregated_under_2_mb():
    scene = running_bond_wall(courses=41, bricks_per_course=25)
    report = check_scene(scene)
    assert len(scene.blocks) > 1000 and report.stable
    markers = step_markers(scene, report, HEADER)
    data = cdr.encode(typestore(), MARKER_TYPE, markers)
    assert len(data) < 2_000_000
    blocks = _by(markers, "blocks")
    assert [m["text"] for m in blocks] == ["support", "stable"]    # one marker per colour
    triangles = sum(len(np.asarray(m["points"])) for m in blocks) // 3
    assert triangles == sum(len(f) - 2 for b in scene.blocks for f in b.faces)
    forces = sum(len(m["points"]) // 2 for m in _by(markers, "forces"))
    assert forces == sum(len(r.polygon) for r in report.interfaces) > 12000
    # a stable wall: no outline or kern is singled out
    assert not _by(markers, "interfaces") and not _by(markers, "kerns")
    decoded = typestore().deserialize_cdr(data, MARKER_TYPE)
    assert len(decoded.markers) == len(markers["markers"])
    assert decoded.markers[1].points[5].x == pytest.approx(blocks[0]["points"][5][0])


def test_report_dicts_and_reports_draw_alike():
    scene = stacked_boxes(0.55)
    report = check_scene(scene)
    state = state_to_dict(scene, "map", 7_000_000_008)
    [from_dicts] = run_markers(state, [report_to_dict(report, HEADER)])
    direct = step_markers(scene, report, HEADER)
    assert [(m["ns"], m["id"], m["text"]) for m in from_dicts["markers"]] == \
        [(m["ns"], m["id"], m["text"]) for m in direct["markers"]]
