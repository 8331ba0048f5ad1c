"""Our verdicts on compas_cra's samples against LMGC90's (issue 24: tests with LMGC90-derived
expectations).

LMGC90 (non-smooth contact dynamics) is the independent reference: ``make bench-lmgc90`` ran
it on each sample, set up as compas_cra's example scripts set it up, and committed its verdicts
to docs/lmgc90_verdicts.json (docs/BENCHMARKS.md section 4 says how a verdict is decided).
This test runs no LMGC90: it loads each sample with the supports, mu and densities recorded
there and asserts that our check stands exactly where LMGC90's simulation stood. A sample
LMGC90 could not decide (its free blocks are not convex: compas_lmgc90 takes one convex
polyhedron per body) is left out, and the test checks that this is why.
"""
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.geometry.block import pose_blocks
from rbe_ros.io.compas import load_compas_assembly, rotated_as_example
from rbe_ros.rbe.solver import SolveOptions

VERDICTS = json.loads((Path(__file__).resolve().parents[1] / "docs" / "lmgc90_verdicts.json")
                      .read_text())["samples"]
DECIDED = {name: r for name, r in VERDICTS.items() if r["lmgc90"] in ("stands", "falls")}
UNDECIDED = {name: r for name, r in VERDICTS.items() if name not in DECIDED}


def sample_scene(samples: Path, record: dict):
    """The sample as make bench-lmgc90 gave it to LMGC90 and to us: its supports, the base
    density, the example script's heavier blocks, and turned as examples/05_wedge.py turns
    type-a..d (``rotation``)."""
    scene = load_compas_assembly(samples / record["file"], supports=record["supports"],
                                 density=record["density"])
    heavier = record["densities"]
    scene = replace(scene, blocks=tuple(replace(b, density=heavier.get(b.id, b.density))
                                        for b in scene.blocks))
    turn = record.get("rotation")
    return rotated_as_example(scene, turn["axis"], turn["deg"]) if turn else scene


def test_lmgc90_decided_the_samples_with_convex_free_blocks():
    """Every sample but snake and bridge (interlocking, non-convex blocks) has a verdict,
    both ways: LMGC90 has some fall and some stand; type-a..d also turned 90 deg about y, x
    and xy30 as compas_cra's examples/05_wedge.py turns them."""
    assert sorted(UNDECIDED) == ["bridge", "snake"]
    assert {r["lmgc90"] for r in DECIDED.values()} == {"stands", "falls"}
    turned = [n for n, r in DECIDED.items() if r.get("rotation")]
    assert len(turned) == 12 and {DECIDED[n]["rotation"]["deg"] for n in turned} == {90.0}
    assert len(DECIDED) == 20


@pytest.mark.parametrize("name", sorted(DECIDED))
def test_our_verdict_is_lmgc90s(samples, name):
    record = DECIDED[name]
    report = check_scene(sample_scene(samples, record),
                         CheckOptions(solve=SolveOptions(mu=record["mu"])))
    assert report.stable == (record["lmgc90"] == "stands"), \
        f"{name}: LMGC90 {record['lmgc90']}, ours {report.status.name}: {report.message}"


@pytest.mark.parametrize("name", sorted(UNDECIDED))
def test_an_undecided_sample_is_one_with_non_convex_free_blocks(samples, name):
    """The blocks LMGC90 had to take as convex hulls are exactly the free non-convex ones."""
    record = UNDECIDED[name]
    blocks = pose_blocks(sample_scene(samples, record).blocks)
    assert record["lmgc90"] == "not comparable" and record["stable"] is None
    assert record["hulls"] == [b.id for b in blocks if not b.support and not b.convex] != []


def test_a_turned_sample_is_turned_as_compas_cra_turns_it(samples):
    """rotate_assembly([0, 0, 0], [0, 1, 0], 90) (compas' right-handed rotation about y) maps
    (x, y, z) to (z, y, -x), written out by hand; xy30 turns about [sqrt 3, 1, 0]: its axis's
    points stay."""
    record = {"file": "type-b.json", "supports": [0, 1], "density": 2000.0, "densities": {}}
    plain = pose_blocks(sample_scene(samples, record).blocks)
    turned = pose_blocks(sample_scene(samples, record | {"rotation": {
        "axis": [0.0, 1.0, 0.0], "deg": 90.0}}).blocks)
    for a, b in zip(plain, turned):
        x, y, z = a.vertices.T
        assert b.vertices == pytest.approx(np.column_stack([z, y, -x]), abs=1e-12)
    axis = np.array([3 ** 0.5, 1.0, 0.0]) / 2
    about = pose_blocks(sample_scene(samples, record | {"rotation": {
        "axis": list(axis * 2), "deg": 90.0}}).blocks)
    for a, b in zip(plain, about):
        along = a.vertices @ axis
        assert b.vertices @ axis == pytest.approx(along, abs=1e-12)
        assert np.linalg.norm(b.vertices - np.outer(along, axis), axis=1) == pytest.approx(
            np.linalg.norm(a.vertices - np.outer(along, axis), axis=1), abs=1e-12)
