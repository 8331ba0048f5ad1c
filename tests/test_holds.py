"""Temporary supports (holds) by step, and the smallest set of blocks to hold, checked
against brute force with the plain checker."""
from __future__ import annotations

import itertools
import json
from dataclasses import replace

import pytest

from rbe_ros import generators
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.options import CheckOptions, HoldSearch
from rbe_ros.analysis.verdict import check
from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.analysis.holds import minimal_holds
from rbe_ros.analysis.pipeline import check_sequence
from rbe_ros.analysis.steps import final_state, sequence_steps
from rbe_ros.cli import main
from rbe_ros.rbe.result import Status
from rbe_ros.scene import Hold, SceneError, make_scene
from rbe_ros.io.scene_json import scene_from_dict, scene_to_dict

WEIGHT = 2000.0 * 0.5 * 9.81          # a 1 x 1 x 0.5 m box of the stack generator


def leaning_stack(n=5, step=0.3):
    """Boxes each ``step`` m further out than the one below: steps 0-2 stand, step 3 tips."""
    return generators.stack(n, offsets=[step * k for k in range(n)])


# --- scene format and steps ---------------------------------------------------------------------

def test_holds_round_trip_and_defaults():
    data = scene_to_dict(leaning_stack())
    data["holds"] = [{"block": "b01", "from_step": 2, "until_step": 4}, {"block": "b03"}]
    scene = scene_from_dict(json.loads(json.dumps(data)))
    assert scene.holds == (Hold("b01", 2, 4), Hold("b03", 0, None))
    assert scene_to_dict(scene)["holds"] == [{"block": "b01", "from_step": 2, "until_step": 4},
                                             {"block": "b03", "from_step": 0}]


@pytest.mark.parametrize("hold, words", [
    ({"block": "nope"}, "no such block"),
    ({"block": "b01", "from_step": -1}, "from_step must be an integer >= 0"),
    ({"block": "b01", "from_step": 2, "until_step": 2}, "until_step must be an integer in (2, 5]"),
    ({"block": "b01", "until_step": 6}, "the scene has 5 steps"),
    ({"block": "b01", "from_step": 1.5}, "from_step must be an integer"),
    ({"block": "b01", "from_step": 5}, "past the last step"),
    ({"block": "b01", "until": 3}, "unknown keys ['until']"),
])
def test_bad_holds_are_refused(hold, words):
    data = scene_to_dict(leaning_stack())
    data["holds"] = [hold]
    with pytest.raises(SceneError) as err:
        scene_from_dict(data)
    assert words in str(err.value)


def test_steps_hold_release_and_remove():
    base = leaning_stack()
    scene = make_scene(base.name, base.blocks, base.gravity, base.sequence,
                       [Hold("b01", 2, 4), Hold("b03", 0, 5), Hold("ground", 0, 5)])
    steps = sequence_steps(scene)
    # a hold ending after the last placement adds a release step that places nothing
    assert [(s.index, s.block) for s in steps] == [(0, "b00"), (1, "b01"), (2, "b02"),
                                                   (3, "b03"), (4, "b04"), (5, "")]
    assert [s.held for s in steps] == [(), (), ("b01",), ("b01", "b03"), ("b03",), ()]
    assert "ground" in steps[4].present and "ground" not in steps[5].present   # taken away
    assert steps[5].present == ("b00", "b01", "b02", "b03", "b04")
    # the state after the last step: nothing held to the end, the temporary support gone
    assert final_state(scene) == (("b00", "b01", "b02", "b03", "b04"), ())


def test_held_blocks_make_the_leaning_stack_stand():
    plain = check_sequence(leaning_stack())
    assert [r.status for r in plain] == [Status.STABLE] * 3 + [Status.TENSION_REQUIRED] * 2
    # step 3 tips about the edge of b00: b01-b03 have their centre of mass 0.6 m out (edge 0.5)
    step3 = plain[3]
    assert step3.held_blocks == () and len(step3.suggested_holds) == 1
    assert step3.max_tension > 1e-3 * WEIGHT
    assert plain[0].suggested_holds == ()
    base = leaning_stack(4)
    held = make_scene(base.name, base.blocks, base.gravity, base.sequence,
                      [Hold(step3.suggested_holds[0], 3)])
    reports = check_sequence(held)
    assert all(r.stable for r in reports), [r.message for r in reports]
    assert [r.held_blocks for r in reports] == [()] * 3 + [step3.suggested_holds]
    # the whole check: the state after the last step, with the hold to the end
    whole = check_scene(held)
    assert whole.stable and whole.held_blocks == step3.suggested_holds
    assert not check_scene(base).stable


def test_subset_held_blocks_are_supports_without_support_interfaces():
    full = Assembly.from_scene(leaning_stack())
    sub = full.subset(["ground", "b00", "b01", "b02"], held=["b00"])
    assert [(b.id, b.support) for b in sub.blocks] == [("ground", True), ("b00", True),
                                                       ("b01", False), ("b02", False)]
    pairs = {(sub.blocks[i.a].id, sub.blocks[i.b].id) for i in sub.interfaces}
    assert pairs == {("b00", "b01"), ("b01", "b02")}          # ground|b00: two supports


# --- minimal holds against brute force ----------------------------------------------------------

def brute_force(assembly):
    """(smallest size, every stable set of that size) by the plain checker on all subsets of
    the free blocks, by increasing size."""
    free = [b.id for b in assembly.blocks if not b.support]
    ids = [b.id for b in assembly.blocks]
    for size in range(len(free) + 1):
        found = [set(c) for c in itertools.combinations(free, size)
                 if check(assembly.subset(ids, held=c)).stable]
        if found:
            return size, found
    raise AssertionError("holding every block must stand")


def semicircular_step(n, k):
    scene = generators.semicircular_arch(n)
    step = sequence_steps(scene)[k]
    return Assembly.from_scene(scene).subset(step.present)


def misplaced_wall():
    wall = generators.running_bond_wall(2, 3)
    blocks = [replace(b, position=b.position + [0.23, 0, 0]) if b.id == "course01_brick03"
              else b for b in wall.blocks]
    return Assembly.from_scene(make_scene("wall", blocks, wall.gravity))


def buttressed_before_key():
    arch = generators.buttressed_arch(voussoirs=7, buttress_courses=3)
    steps = sequence_steps(arch)
    return Assembly.from_scene(arch).subset(steps[-2].present)


def zigzag_stack():
    offsets = [0.0, 0.3, 0.6, 0.9, 0.6, 0.3, 0.0, 0.3, 0.6, 0.9, 1.2, 0.9]
    return Assembly.from_scene(generators.stack(12, offsets=offsets))


SCENES = {
    "leaning stack (5)": (lambda: Assembly.from_scene(leaning_stack()), 1),
    "semicircular arch, 4 of 7 voussoirs": (lambda: semicircular_step(7, 3), 2),
    "semicircular arch, 6 of 9 voussoirs": (lambda: semicircular_step(9, 5), 2),
    "wall with a misplaced brick (8)": (misplaced_wall, 1),
    "buttressed arch before the key-stone (10)": (buttressed_before_key, 2),
    "zig-zag stack (12)": (zigzag_stack, 1),
    "semicircular arch, 12 of 13 voussoirs": (lambda: semicircular_step(13, 11), 2),
}


@pytest.mark.parametrize("name", sorted(SCENES))
def test_minimal_holds_equal_brute_force(name):
    make, expected = SCENES[name]
    assembly = make()
    free = [b.id for b in assembly.blocks if not b.support]
    assert len(free) <= 12
    size, solutions = brute_force(assembly)
    assert size == expected
    result = minimal_holds(assembly, search=HoldSearch(max_size=4, max_checks=10_000))
    assert result.exact and result.stands
    assert len(result.blocks) == size
    assert set(result.blocks) in solutions


def test_buttressed_arch_holds_the_voussoirs_next_to_the_key():
    result = minimal_holds(buttressed_before_key())
    assert result.exact and result.blocks == ("v02", "v04")   # key-stone v03 of 7


def test_greedy_beyond_the_budget_stands_and_is_minimal_by_inclusion():
    assembly = semicircular_step(9, 5)
    result = minimal_holds(assembly, search=HoldSearch(max_size=0, max_checks=0))
    assert not result.exact and result.stands
    ids = [b.id for b in assembly.blocks]
    assert check(assembly.subset(ids, held=result.blocks)).stable
    for drop in result.blocks:                          # every hold is needed
        rest = [b for b in result.blocks if b != drop]
        assert not check(assembly.subset(ids, held=rest)).stable
    exact = minimal_holds(assembly)
    assert len(result.blocks) >= len(exact.blocks) == 2


def test_suggestions_can_be_switched_off():
    options = CheckOptions(holds=HoldSearch(enabled=False))
    assert all(r.suggested_holds == () for r in check_sequence(leaning_stack(), options))


def test_cli_check_json_names_the_holds(tmp_path, capsys):
    path = tmp_path / "stack.json"
    data = scene_to_dict(leaning_stack())
    data["holds"] = [{"block": "b02", "from_step": 4}]
    path.write_text(json.dumps(data))
    assert main(["check", str(path), "--sequence", "--json"]) == 0
    steps = json.loads(capsys.readouterr().out)["reports"]
    assert [s["held_blocks"] for s in steps] == [[]] * 4 + [["b02"]]
    # b03 and b04 (centre of mass 1.05 m out) stand on the held b02 (0.1 .. 1.1 m)
    assert [s["stable"] for s in steps] == [True, True, True, False, True]
    assert len(steps[3]["suggested_holds"]) == 1 and steps[4]["suggested_holds"] == []
    assert main(["check", str(path), "--sequence"]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[-1].startswith("4 ") and table[-1].endswith("| held: b02")
    assert f"| to stand, hold: {steps[3]['suggested_holds'][0]}" in table[-2]
