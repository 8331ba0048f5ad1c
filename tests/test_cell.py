"""Plans for a robot cell (rbe_ros/cell.py, analysis/grips.py, analysis/timeline.py): the
7-voussoir arch planned for three robots, its timeline re-checked from the export, busy
robots counted from the actions, grip faces and gripper boxes checked with trimesh (an
independent geometry library), a held block's robot wrench against its closed form, the
reach of a wall's robots, UR10 inverse kinematics verified by forward kinematics, bad cell
files (one line, exit 2)."""
from __future__ import annotations

import json

import numpy as np
import pinocchio as pin
import pytest
import trimesh
from compas.geometry import Frame
from compas_fab.robots import FrameTarget, TargetMode
from scipy.spatial.transform import Rotation

from rbe_ros import generators
from rbe_ros.analysis.assembly import Assembly
from rbe_ros.analysis.grips import GripChooser, hold_torque, robot_wrench
from rbe_ros.analysis.kinematics import load_arm, solve_ik
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.analysis.planning import plan_sequence
from rbe_ros.analysis.timeline import Busy, CellCheck, CellSteps, StateChecks
from rbe_ros.cell import Cell, CellError, Robot, Tool, cell_from_dict
from rbe_ros.cli import main
from rbe_ros.io.cell_file import parse_cell
from rbe_ros.io.markers import PULL, PUSH, cell_markers
from rbe_ros.io.scene_json import scene_to_dict
from rbe_ros.scene import box_block, make_scene

G = 9.81
TOOL = {"box": [0.1, 0.1, 0.15], "tcp": [0.0, 0.0, 0.15], "mass": 2.0}
ARCH_CELL = {"robots": [
    {"name": "r1", "base": [1.5, -1.5, 0.0], "reach": 3.0, "payload_force": 3000,
     "payload_torque": 1500, "tool": TOOL},
    {"name": "r2", "base": [-1.5, -1.5, 0.0], "reach": 3.0, "payload_force": 3000,
     "payload_torque": 1500, "tool": TOOL},
    {"name": "r3", "base": [0.0, 1.5, 0.0], "reach": 3.0, "payload_force": 3000,
     "payload_torque": 1500, "tool": TOOL}]}


def write(tmp_path, name, data) -> str:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return str(path)


def busy_per_state(timeline) -> list[int]:
    """Robots busy after each action, counted here from the actions: a robot is busy with a
    block from its place (or hold) to its release of that block, and never places while
    busy (asserted)."""
    holding: dict[str, str] = {}
    out = []
    for a in timeline:
        if a["action"] == "place":
            assert a["robot"] not in holding, f"{a['robot']} places while holding"
            holding[a["robot"]] = a["block"]
        elif a["action"] == "hold":
            assert holding.get(a["robot"], a["block"]) == a["block"]
            holding[a["robot"]] = a["block"]
        else:
            assert holding.pop(a["robot"]) == a["block"]
        out.append(len(holding))
    return out


def pose_of(d) -> tuple[np.ndarray, np.ndarray]:
    p, q = d["pose"]["position"], d["pose"]["orientation"]
    return (np.array([p["x"], p["y"], p["z"]]),
            Rotation.from_quat([q["x"], q["y"], q["z"], q["w"]]).as_matrix())


def meshes(scene) -> dict[str, trimesh.Trimesh]:
    out = {}
    for b in scene.blocks:
        tri = [[f[0], f[i], f[i + 1]] for f in b.faces for i in range(1, len(f) - 1)]
        world = Rotation.from_quat(b.orientation).apply(b.vertices) + b.position
        out[b.id] = trimesh.Trimesh(world, tri, process=True)
    return out


def inside(mesh: trimesh.Trimesh, points) -> np.ndarray:
    """Which ``points`` are inside convex ``mesh`` (behind every face plane of trimesh's
    triangles and normals)."""
    points = np.atleast_2d(points)
    offsets = np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles[:, 0])
    return np.all(points @ mesh.face_normals.T - offsets < -1e-9, axis=1)


def on_face(mesh: trimesh.Trimesh, point, normal) -> bool:
    """Whether ``point`` lies on a face of convex ``mesh`` with outward ``normal``: in that
    face's plane, and just behind it inside the mesh."""
    offsets = np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles[:, 0])
    same = mesh.face_normals @ normal > 1 - 1e-6
    planar = np.abs(mesh.face_normals[same] @ point - offsets[same]) < 1e-6
    return bool(planar.any() and inside(mesh, point - 1e-4 * np.asarray(normal))[0])


def assert_grips_free(scene, cell: dict, timeline) -> int:
    """Every grip (place and hold) on a face of its block free of the blocks present while
    it is held (the supports, and every block placed before its release), and its robot's
    gripper box clear of them, by trimesh: points just off the face around the grip and a
    grid through the box are inside none of them. Returns the grips checked."""
    bodies = meshes(scene)
    supports = [b.id for b in scene.blocks if b.support]
    tools = {r["name"]: r["tool"] for r in cell["robots"]}
    checked = 0
    for i, a in enumerate(timeline):
        if a["action"] == "release":
            continue
        end = next((j for j in range(i + 1, len(timeline)) if timeline[j]["action"] == "release"
                    and timeline[j]["block"] == a["block"]), len(timeline))
        present = supports + [b["block"] for b in timeline[:end + 1] if b["action"] == "place"]
        point, rot = pose_of(a["grip"])
        normal = -rot[:, 2]                       # the tool's z points into the face
        assert on_face(bodies[a["block"]], point, normal)
        u, v = rot[:, 0], rot[:, 1]
        near = np.array([point + 2e-3 * normal + s * u + t * v
                         for s in (-0.02, 0, 0.02) for t in (-0.02, 0, 0.02)])
        size = np.asarray(tools[a["robot"]]["box"])
        axes = np.linspace(-0.45, 0.45, 5)
        grid = np.array([[x, y, z] for x in axes for y in axes for z in axes]) * size
        centre = point + normal * (size[2] / 2 + 1e-3)
        box = centre + grid @ rot.T
        for k in present:
            if k == a["block"]:
                continue
            assert not inside(bodies[k], near).any(), f"grip of {a['block']} touches {k}"
            assert not inside(bodies[k], box).any(), f"gripper at {a['block']} hits {k}"
        checked += 1
    return checked


@pytest.fixture(scope="module")
def arch_plan(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cell_arch")
    scene_path = write(tmp, "arch.json", scene_to_dict(generators.semicircular_arch(7)))
    cell_path = write(tmp, "cell.json", ARCH_CELL)
    out = tmp / "plan.json"
    return tmp, scene_path, cell_path, out


def test_the_arch_for_three_robots_timeline_rechecked(arch_plan, capsys):
    tmp, scene_path, cell_path, out = arch_plan
    capsys.readouterr()
    assert main(["plan", scene_path, "--cell", cell_path, "--json", "-o", str(out)]) == 0
    result = json.loads(capsys.readouterr().out)
    timeline = result["timeline"]
    assert result["feasible"] and result["robots"] == ["r1", "r2", "r3"]
    assert result["order"] == ["v00", "v06", "v01", "v05", "v02", "v04", "v03"]
    busy = busy_per_state(timeline)
    assert max(busy) == 3 and busy[-1] == 0           # three robots at step 4, none at the end
    assert all(a["stable"] for a in timeline)
    # every block placed once; step 4 needs the third robot: v01, v05 held while v02 placed
    assert sorted(a["block"] for a in timeline if a["action"] == "place") == sorted(
        result["order"])
    at4 = [a for a in timeline if a["step"] == 4]
    assert [a["action"] for a in at4] == ["place", "hold", "release"]
    assert at4[0]["robot"] == "r3" and at4[2]["block"] == "v01"
    # the step summaries carry the hold wrenches: step 4 holds v02 and v05 (README table)
    step4 = result["steps"][4]
    forces = {w["block"]: np.linalg.norm(w["force"]) for w in step4["hold_wrenches"]}
    # held still, v05 carries about its weight (1277 N), less what v06 under it takes
    assert set(forces) == {"v02", "v05"} and 1150 < forces["v05"] < 1277
    # the export: capacities and grips kept in the planned scene, the timeline re-checked
    data = json.loads(out.read_text())
    assert data["timeline"] == timeline and data["cell"]["robots"][0]["name"] == "r1"
    assert all(h["max_force"] == pytest.approx(3000 - 2 * G) and "grip" in h
               for h in data["holds"])
    capsys.readouterr()
    assert main(["check", str(out), "--timeline", "--json", "--strict"]) == 0
    check = json.loads(capsys.readouterr().out)
    assert check["stable"] and check["states"] == len(timeline)
    assert [s["busy"] for s in check["timeline"]] == busy
    assert assert_grips_free(generators.semicircular_arch(7), ARCH_CELL, timeline) == 11


def test_exported_frames_as_compas_fab_targets(arch_plan, capsys):
    """compas Frames and compas_fab FrameTargets built from the export: the grip frame's
    origin on the grip face, its z axis into the block, pre-grip backed off 0.1 m along the
    face normal, the approach start against the insertion direction (down: above) over the
    insertion check's distance (from where the block is clear of the bounding boxes of the
    blocks placed before it: its bottom up to their top)."""
    tmp, scene_path, cell_path, out = arch_plan
    if not out.exists():
        main(["plan", scene_path, "--cell", cell_path, "-o", str(out)])
    data = json.loads(out.read_text())
    bodies = meshes(generators.semicircular_arch(7))
    places = [a for a in data["timeline"] if a["action"] == "place"]
    for a in places:
        frames = {}
        for key in ("grip", "pre_grip", "approach"):
            p, q = a[key]["pose"]["position"], a[key]["pose"]["orientation"]
            frames[key] = Frame.from_quaternion([q["w"], q["x"], q["y"], q["z"]],
                                                [p["x"], p["y"], p["z"]])
            assert FrameTarget(frames[key], TargetMode.TOOL).target_frame == frames[key]
        grip = frames["grip"]
        z = np.array(grip.zaxis)
        assert on_face(bodies[a["block"]], np.array(grip.point), -z)
        back = np.array(frames["pre_grip"].point) - np.array(grip.point)
        assert back == pytest.approx(-0.1 * z, abs=1e-9)
        start = np.array(frames["approach"].point) - np.array(grip.point)
        before = data["sequence"][:data["sequence"].index(a["block"])]
        top = max((bodies[b].bounds[1][2] for b in before), default=-np.inf)
        distance = max(0.0, top - bodies[a["block"]].bounds[0][2])
        assert start == pytest.approx([0.0, 0.0, distance], abs=1e-9)


def test_a_held_block_robot_wrench_closed_form():
    """A block held by its +x face with no contact: the block needs m g up and, about the
    grip, M = -(c - p) x W = (0, m g a / 2, 0); the robot carries its tool too, m_t g up at
    the box centre d = sz / 2 + 1 mm off the face: in tool axes (x up, y = y, z = -x)
    F = ((m + m_t) g, 0, 0), M = (0, m g a / 2 - m_t g d, 0)."""
    a, m, tool_mass, depth = 0.4, 50.0, 3.0, 0.2
    ground = box_block("ground", (1, 1, 0.1), (0, 0, -5), density=2000, support=True)
    block = box_block("b", (a, 0.3, 0.2), (0, 0, 1.0), mass=m)
    scene = make_scene("held", [ground, block])
    robot = Robot("r", (3.0, 0.0, 1.0), 4.0, 1000.0, 200.0,
                  Tool((0.1, 0.1, depth), (0, 0, depth), tool_mass))
    cell = Cell((robot,))
    assembly = Assembly.from_scene(scene)
    grip, why = GripChooser(assembly, cell).choose("b", robot)
    assert why == "" and grip.point == pytest.approx([a / 2, 0, 1.0])
    report = StateChecks(cell, assembly, scene, CheckOptions())(("ground", "b"),
                                                               (("b", Busy("r", grip)),))
    assert report.stable
    w = report.hold_wrenches[0]
    wrench = robot_wrench(robot, grip, w.force, w.torque, scene.gravity)
    assert wrench.force_world == pytest.approx([0, 0, m * G], abs=1e-3 * m * G)
    assert wrench.torque_world == pytest.approx([0, m * G * a / 2, 0], abs=1e-3 * m * G)
    d = depth / 2 + 1e-3
    assert wrench.force_tool == pytest.approx([(m + tool_mass) * G, 0, 0], abs=0.1)
    assert wrench.torque_tool == pytest.approx([0, m * G * a / 2 - tool_mass * G * d, 0],
                                               abs=0.05)
    assert wrench.utilisation == pytest.approx((m + tool_mass) * G / 1000.0, rel=1e-3)



def test_a_block_to_hold_is_gripped_where_its_hold_torque_is_least():
    """A box on the ground (a = 0.4 m along x, 50 kg), the robot's base beside it on +x:
    to place it and let go the robot grips the +x face, facing its base, where the box's
    weight and the tool's need |M| = m g a / 2 - m_t g d about the TCP (d the tool box's
    centre off the face: sz / 2 + 1 mm); to hold it, the top face, the TCP above both
    centres of mass: no torque (closed form), the payload's torque left whole for what
    leans on the box."""
    a, m, tool_mass, depth = 0.4, 50.0, 3.0, 0.2
    ground = box_block("ground", (2, 2, 0.1), (0, 0, -0.05), density=2000, support=True)
    scene = make_scene("hold_face", [ground, box_block("b", (a, 0.3, 0.2), (0, 0, 0.1),
                                                           mass=m)])
    cell = cell_from_dict({"robots": [{"name": "r", "base": [3.0, 0.0, 0.1], "reach": 4.0,
                                       "payload_force": 1000, "payload_torque": 200,
                                       "tool": {"box": [0.1, 0.1, depth], "tcp": [0, 0, depth],
                                                "mass": tool_mass}}]})
    assembly = Assembly.from_scene(scene)
    chooser = GripChooser(assembly, cell)
    robot = cell.robots[0]
    present = frozenset({"ground", "b"})
    placed, _ = chooser.choose("b", robot, present, carry=True)
    held, _ = chooser.choose("b", robot, present, carry=True, hold=True)
    assert placed.normal == pytest.approx([1, 0, 0]) and held.normal == pytest.approx([0, 0, 1])
    box = assembly.block("b")
    d = depth / 2 + 1e-3
    assert hold_torque(robot, placed, box, assembly.gravity) == pytest.approx(
        m * G * a / 2 - tool_mass * G * d, rel=1e-9)
    assert hold_torque(robot, held, box, assembly.gravity) == pytest.approx(0.0, abs=1e-9)


def test_check_timeline_rechecks_a_place_carry_against_the_payload(tmp_path, capsys):
    """``check --timeline`` re-checks what a placing robot carries: a block resting on the
    ground placed by its +x face, the robot's payload lowered in the export below the carry:
    HOLD_EXCEEDED naming the robot, the block, the wrench and the payload, in closed form
    (tool axes x up, z = -x): F = (m + m_t) g, M = (0, m g a / 2 - m_t g d, 0), d the tool
    box's centre off the face (sz / 2 + 1 mm); the state after the place itself stands."""
    a, m, tool_mass, depth = 0.4, 50.0, 3.0, 0.2
    ground = box_block("ground", (2, 2, 0.1), (0, 0, -0.05), density=2000, support=True)
    scene = make_scene("carry", [ground, box_block("b", (a, 0.3, 0.2), (0, 0, 0.1), mass=m)])
    cell = {"robots": [{"name": "r", "base": [3.0, 0.0, 0.1], "reach": 4.0,
                        "payload_force": 1000, "payload_torque": 200,
                        "tool": {"box": [0.1, 0.1, depth], "tcp": [0, 0, depth],
                                 "mass": tool_mass}}]}
    out = tmp_path / "plan.json"
    assert main(["plan", write(tmp_path, "s.json", scene_to_dict(scene)), "--cell",
                 write(tmp_path, "c.json", cell), "-o", str(out), "--json"]) == 0
    capsys.readouterr()
    assert main(["check", str(out), "--timeline", "--json", "--strict"]) == 0
    assert json.loads(capsys.readouterr().out)["stable"]
    data = json.loads(out.read_text())
    data["cell"]["robots"][0]["payload_force"] = 400.0
    assert main(["check", write(tmp_path, "low.json", data), "--timeline", "--json",
                 "--strict"]) == 1
    rows = json.loads(capsys.readouterr().out)["timeline"]
    assert [(r["action"], r["status"]) for r in rows] == [("place", "HOLD_EXCEEDED"),
                                                          ("release", "STABLE")]
    message = rows[0]["message"]
    force = (m + tool_mass) * G
    assert f"r carrying block b to its pose needs |F| {force:.4g} N (payload 400 N)" in message
    torque = [float(x) for x in message.split("torque (")[1].split(")")[0].split(",")]
    d = depth / 2 + 1e-3
    # 4 significant digits in the message
    assert torque == pytest.approx([0, m * G * a / 2 - tool_mass * G * d, 0], abs=0.01)
    assert f"|M| {abs(torque[1]):.4g} N m (payload 200 N m)" in message


def wall_cell(right_reach: float) -> dict:
    tool = {"box": [0.06, 0.06, 0.1], "tcp": [0, 0, 0.1], "mass": 1.0}
    return {"robots": [
        {"name": "left", "base": [-0.5, -1.0, 0.0], "reach": 2.6, "payload_force": 500,
         "payload_torque": 100, "tool": tool},
        {"name": "right", "base": [4.5, -1.0, 0.0], "reach": right_reach,
         "payload_force": 500, "payload_torque": 100, "tool": tool}]}


def test_a_wall_side_out_of_reach_goes_to_the_other_robot_or_fails(tmp_path, capsys):
    """A 4 m wall (2 courses of 10 bricks): the left robot reaches x < 2 m or so, the
    right one the rest: each brick is placed by a robot within reach of its grip; with the
    right robot's reach cut, the plan fails at the first brick neither reaches, naming it
    and both robots."""
    wall = generators.running_bond_wall(2, 10)
    scene_path = write(tmp_path, "wall.json", scene_to_dict(wall))
    bases = {r["name"]: np.array(r["base"]) for r in wall_cell(3.0)["robots"]}
    for reach, feasible in ((3.0, True), (1.0, False)):
        cell = wall_cell(reach)
        capsys.readouterr()
        code = main(["plan", scene_path, "--cell", write(tmp_path, "c.json", cell), "--json"])
        result = json.loads(capsys.readouterr().out)
        assert (code == 0) == feasible == result["feasible"]
        reaches = {r["name"]: r["reach"] for r in cell["robots"]}
        for a in result["timeline"]:
            point, _ = pose_of(a["grip"])
            assert np.linalg.norm(point - bases[a["robot"]]) <= reaches[a["robot"]]
        robots = {a["robot"] for a in result["timeline"]}
        if feasible:
            assert robots == {"left", "right"}
        else:
            message = result["message"]
            block = message.split("no free robot can grip ")[1].split(":")[0]
            assert block in wall.sequence and block not in result["order"]
            assert "left cannot grip" in message and "right cannot grip" in message
            assert "reach" in message


UR10 = "example-robot-data:ur_description/urdf/ur10_robot.urdf"


def test_ur10_grips_of_the_arch_have_inverse_kinematics(tmp_path, capsys):
    """Two UR10s (example-robot-data) in front of the arch: every grip frame of the plan has
    a joint solution, verified here by pinocchio's forward kinematics of the tip (tool0)
    plus the TCP offset against the exported grip pose."""
    tool = {"box": [0.08, 0.08, 0.1], "tcp": [0, 0, 0.1], "mass": 1.0}
    cell = {"robots": [{"name": n, "base": [x, -0.8, 0.4], "reach": 1.3, "urdf": UR10,
                        "payload_force": 3000, "payload_torque": 800, "tool": tool}
                       for n, x in (("ur_a", 0.6), ("ur_b", -0.6), ("ur_c", 0.0))]}
    scene_path = write(tmp_path, "arch.json", scene_to_dict(generators.semicircular_arch(7)))
    capsys.readouterr()
    main(["plan", scene_path, "--cell", write(tmp_path, "ur.yaml", json.dumps(cell)),
          "--json"])
    result = json.loads(capsys.readouterr().out)
    assert result["feasible"], result["message"]
    assert assert_joint_solutions(parse_cell(json.dumps(cell)), result["timeline"]) == 11


def assert_joint_solutions(cell, timeline) -> int:
    """Every grip of ``timeline`` (not a release) has a joint solution of its robot's URDF:
    pinocchio's forward kinematics of the tip, turned and moved to the robot's base, plus
    the TCP offset, is the grip pose. Returns the grips checked."""
    grips = [a for a in timeline if a["action"] != "release"]
    for a in grips:
        robot = cell.robot(a["robot"])
        point, rot = pose_of(a["grip"])
        q = solve_ik(robot, point, rot)
        model, tip = load_arm(robot)
        data = model.createData()
        pin.framesForwardKinematics(model, data, q)
        yaw = robot.base_yaw
        base = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0],
                         [0, 0, 1]])
        flange = base @ data.oMf[tip].rotation
        tcp = base @ data.oMf[tip].translation + np.asarray(robot.base) \
            + flange @ np.asarray(robot.tool.tcp)
        assert tcp == pytest.approx(point, abs=1e-3)
        assert flange == pytest.approx(rot, abs=1e-3)
    return len(grips)


BAD = [
    ("robots: [{name: r1, base: [0, 0, 0], reach: 2, payload_torque: 5}]",
     "cell: robot 'r1': missing 'payload_force'"),
    ('{"robots": [{"name": "r1", "base": [0, 0, 0], "reach": 2, "payload_force": -3, '
     '"payload_torque": 5}]}', "'payload_force' must be a number >= 0, got -3"),
    ("robots: [{name: r1, base: [0, 0, 1.1], reach: 2, payload_force: 9, payload_torque: 5}]",
     "'base' [0.0, 0.0, 1.1] is inside block v03"),
    ("robots: [{name: r1, base: [3, 0, 0], reach: 2, payload_force: 9, payload_torque: 5, "
     "urdf: missing.urdf}]", "'urdf' "),
    ("robots: [{name: r1, base: [3, 0, 0], reach: 2, payload_force: 9, payload_torque: 5, "
     "urdf: bad.urdf}]", "does not contain a valid URDF model"),
    ("robots: [{name: r1, base: [0, 0, 0]\n  reach: 2", "cell: YAML does not parse (line"),
]


@pytest.mark.parametrize("text, expected", BAD)
def test_bad_cell_files_one_line_exit_2(tmp_path, capfd, text, expected):
    """One line on the process's stderr (fd 2: the URDF parser's own C++ output too)."""
    scene_path = write(tmp_path, "arch.json", scene_to_dict(generators.semicircular_arch(7)))
    cell_path = write(tmp_path, "cell.yaml", text)
    write(tmp_path, "bad.urdf", '<robot name="x"><link name=')
    capfd.readouterr()
    assert main(["plan", scene_path, "--cell", cell_path]) == 2
    err = capfd.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert err.startswith("rbe-ros: error: cell") and expected in err


def test_an_exported_timeline_naming_an_unknown_robot(arch_plan, tmp_path, capsys):
    tmp, scene_path, cell_path, out = arch_plan
    if not out.exists():
        main(["plan", scene_path, "--cell", cell_path, "-o", str(out)])
    data = json.loads(out.read_text())
    data["timeline"][3]["robot"] = "r9"
    capsys.readouterr()
    assert main(["check", write(tmp_path, "bad.json", data), "--timeline"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "rbe-ros: error: cell: unknown robot 'r9' (the cell has r1, r2, r3)"


def test_cell_fields_and_robot_count():
    cell = cell_from_dict(ARCH_CELL)
    assert cell.names == ("r1", "r2", "r3") and cell.robots[0].tool.mass == 2.0
    with pytest.raises(CellError, match="appears twice"):
        cell_from_dict({"robots": [ARCH_CELL["robots"][0]] * 2})
    # two robots of 1500 N: one holds while one places; at step 4 the crown v03, held
    # still alone once v02 is released, carries its weight and v02's thrust (the least the
    # placement test admits), 1619 N, beyond r1's 1500 N payload less its tool's 19.6 N:
    # the plan names both (a voussoir alone needs its weight and the tool's, 1297 N)
    robots = [dict(r, payload_force=1500) for r in ARCH_CELL["robots"][:2]]
    plan = plan_sequence(generators.semicircular_arch(7), 1,
                         cell=cell_from_dict({"robots": robots}))
    assert not plan.feasible and plan.failed_step == 4
    assert "(r1 holding v03 beyond its payload): hold exceeded" in plan.message
    assert "needs |F| 1619 N (capacity 1480 N)" in plan.message
    assert max(busy_per_state([{"action": a.action, "robot": a.robot, "block": a.block}
                               for a in plan.timeline.actions])) <= 2


def test_markers_and_view_of_the_arch_plan(arch_plan, capsys):
    """The state after r3 places v02 (step 4): three robot bases, the gripper boxes of the
    three busy robots behind their grips, r3's force on v02 as an arrow from the grip (its
    colour: push when the force points into the face), the hover text naming robot, block,
    force and torque; the HTML view's per-robot table and arrows."""
    tmp, scene_path, cell_path, out = arch_plan
    if not out.exists():
        main(["plan", scene_path, "--cell", cell_path, "-o", str(out)])
    data = json.loads(out.read_text())
    timeline, cell = data["timeline"], cell_from_dict(data["cell"])
    index = next(k for k, a in enumerate(timeline) if a["action"] == "place"
                 and a["block"] == "v02")
    markers = cell_markers(cell, timeline, index, timeline[index]["grip"]["header"], 0.5)
    kinds = [(m["ns"], m["type"]) for m in markers]
    assert kinds.count(("robots", 3)) == 3 and kinds.count(("grippers", 1)) == 3
    act = timeline[index]
    point, rot = pose_of(act["grip"])
    box = next(m for m in markers if m["ns"] == "grippers" and m["id"] == 2)      # r3
    centre = np.array([box["pose"]["position"][k] for k in "xyz"])
    assert centre == pytest.approx(point - rot[:, 2] * (0.15 / 2 + 1e-3))
    arrow = next(m for m in markers if m["ns"] == "robot_wrenches" and m["type"] == 0)
    force = np.array([act["wrench_world"]["force"][k] for k in "xyz"])
    tail, tip = arrow["points"]
    assert tail == pytest.approx(point) and np.cross(tip - tail, force) == pytest.approx(
        np.zeros(3), abs=1e-6)
    push = force @ rot[:, 2] >= 0
    assert tuple(arrow["color"][k] for k in "rgba") == (PUSH if push else PULL)
    text = next(m["text"] for m in markers if m["ns"] == "robot_wrenches" and m["type"] == 9)
    assert text.startswith(f"r3 place v02: |F| {np.linalg.norm(force):.0f} N on the block")
    # the page: the per-robot table and the robots' arrows at step 4
    capsys.readouterr()
    page = tmp / "view.html"
    assert main(["view", str(out), "-o", str(page)]) == 0
    view = json.loads(page.read_text().split('type="application/json">')[1]
                      .split("</script>")[0].replace("<\\/", "</"))
    table = view["robot_tables"][0]
    assert table["robots"] == ["r1", "r2", "r3"]
    assert table["rows"][4] == [4, "release v01", "-", "place v02; hold v02"]
    step4 = view["steps"][4]
    # place and hold of v02 are one state: one arrow
    assert [a["name"].split(":")[0] for a in step4["robot_arrows"]] == ["r3 place v02"]
    assert {ln["name"] for ln in step4["lines"]} >= {"base of r1", "gripper of r3"}
    # each robot named above its base; the legend explains the robots' colours
    assert sorted((lb["text"], lb["x"], lb["y"]) for lb in step4["labels"]) == [
        (r.name, pytest.approx(r.base[0]), pytest.approx(r.base[1])) for r in cell.robots]
    assert {"robot base", "gripper"} <= {e["name"] for e in view["line_legend"]}


def test_plan_output_keeps_the_hold_capacities(tmp_path, capsys):
    """Without a cell, ``plan -o`` writes the capacities the plan was checked under into
    each hold, and ``check --sequence`` of the file checks with them (the arch's largest hold,
    a voussoir's weight, 1277 N, held still at steps 2 and 3, within 1400 N)."""
    scene_path = write(tmp_path, "arch.json", scene_to_dict(generators.semicircular_arch(7)))
    out = tmp_path / "planned.json"
    assert main(["plan", scene_path, "--max-held", "2", "--hold-force-max", "1400",
                 "--hold-torque-max", "300", "-o", str(out)]) == 0
    holds = json.loads(out.read_text())["holds"]
    assert holds and all(h["max_force"] == 1400 and h["max_torque"] == 300 for h in holds)
    capsys.readouterr()
    assert main(["check", str(out), "--sequence", "--json", "--strict"]) == 0
    reports = json.loads(capsys.readouterr().out)["reports"]
    assert max(w["utilisation"] for r in reports for w in r["hold_wrenches"]) \
        == pytest.approx(1276.9 / 1400, abs=0.01)


def test_a_hand_over_releases_before_the_placement_and_is_checked():
    """Two robots hold v01 and v05 after step 3 of the arch's K = 2 plan; to place v02 one
    must let go first: r1 releases v01 (the hold step 4 drops) before it places v02. That
    hand-over state (v02 absent, v05 held alone) falls, and the planner's hook says so; with
    a third robot there is no hand-over."""
    arch = generators.semicircular_arch(7)
    assembly = Assembly.from_scene(arch)
    order = ("v00", "v06", "v01", "v05")
    held = ((), (), ("v01",), ("v01", "v05"))
    two = cell_from_dict({"robots": ARCH_CELL["robots"][:2]})
    steps = CellSteps(two, assembly)
    busy = {}
    supports = ("support_right", "support_left")
    for k, (block, now) in enumerate(zip(order, held)):
        _, busy = steps.step(k, block, busy, now, supports + order[:k])
    assert {b: h.robot for b, h in busy.items()} == {"v01": "r1", "v05": "r2"}
    acts, after = steps.step(4, "v02", busy, ("v02", "v05"), supports + order)
    assert [(a.action, a.robot, a.block, a.before) for a in acts] == [
        ("release", "r1", "v01", True), ("place", "r1", "v02", False),
        ("hold", "r1", "v02", False)]
    assert [[b for b, _ in a.busy] for a in acts] == [["v05"], ["v05", "v02"],
                                                      ["v05", "v02"]]
    hook = CellCheck(two, assembly, arch, CheckOptions())
    why = hook(order, held, "v02", ("v02", "v05"))
    assert why.startswith("step 4: the hand-over state after r1 releases v01 (v02 not yet "
                          "placed) is ")
    # the same state checked here: v00..v05 present, v05 held alone
    alone = StateChecks(two, assembly, arch, CheckOptions())(
        ("support_right", "support_left", *order), (("v05", busy["v05"]),))
    assert not alone.stable and alone.status.name in why
    three = cell_from_dict(ARCH_CELL)
    assert CellCheck(three, assembly, arch, CheckOptions())(
        order, held, "v02", ("v02", "v05")) == ""


def test_a_top_grip_is_free_while_held_and_blocks_the_course_above(tmp_path, capsys):
    """Bricks 0.1 m high and a gripper 0.3 m wide: beside a brick the gripper hits the
    footing or its neighbours, so each brick is taken by its top face, free while the brick
    is held (released at once: the course above comes later); a brick of the course above
    lands on that face, so it may not be placed while a robot still grips the one below."""
    wall = generators.running_bond_wall(2, 4)
    tool = {"box": [0.3, 0.3, 0.1], "tcp": [0, 0, 0.1], "mass": 1.0}
    cell = {"robots": [{"name": "top", "base": [0.8, -0.6, 1.2], "reach": 2.0,
                        "payload_force": 500, "payload_torque": 100, "tool": tool}]}
    capsys.readouterr()
    assert main(["plan", write(tmp_path, "wall.json", scene_to_dict(wall)), "--cell",
                 write(tmp_path, "c.json", cell), "--json"]) == 0
    timeline = json.loads(capsys.readouterr().out)["timeline"]
    places = [a for a in timeline if a["action"] == "place"]
    assert len(places) == 9
    assert all(pose_of(a["grip"])[1][:, 2] == pytest.approx([0, 0, -1]) for a in places)
    assert assert_grips_free(wall, cell, timeline) == 9
    # the finished wall has no free top face on the first course: only present blocks count
    assembly = Assembly.from_scene(wall)
    chooser = GripChooser(assembly, cell_from_dict(cell))
    robot = chooser.cell.robots[0]
    grip, why = chooser.choose("course00_brick01", robot, frozenset({"footing",
                                                                    "course00_brick00"}))
    assert grip is not None and grip.normal == pytest.approx([0, 0, 1])
    assert chooser.choose("course00_brick01", robot)[0] is None
    assert chooser.in_the_way("course01_brick01", robot, grip)
    assert not chooser.in_the_way("course00_brick03", robot, grip)
    # with a second robot to place it: kept, the hold is in the way; dropped, it is let go
    # first (a hand-over state)
    two = cell_from_dict({"robots": [cell["robots"][0], {**cell["robots"][0], "name": "b"}]})
    steps = CellSteps(two, assembly)
    present = ("footing", *wall.sequence[:4])
    busy = {"course00_brick01": Busy("top", grip)}
    with pytest.raises(Exception, match="course01_brick01 would land on top's grip of "
                                        "course00_brick01, which the step holds"):
        steps.step(5, "course01_brick01", busy, ("course00_brick01",), present)
    acts, _ = steps.step(5, "course01_brick01", busy, (), present)
    assert [(a.action, a.block, a.before) for a in acts][:2] == [
        ("release", "course00_brick01", True), ("place", "course01_brick01", False)]


def test_a_carried_block_closed_form_and_a_robot_too_weak_to_carry_it(tmp_path, capsys):
    """A block resting on the ground once placed, carried there by its +x face (no hold:
    the ground bears it after): the place action's wrench is its whole weight m g up at the
    TCP, about which it hangs a / 2 off (its centre of mass), M = (b - p) x (-W) = (0,
    m g a / 2, 0); with the tool's weight m_t g up at its box centre d = sz / 2 + 1 mm
    behind the face, in tool axes (x up, y = y, z = -x) F = ((m + m_t) g, 0, 0), M = (0,
    m g a / 2 - m_t g d, 0). A robot of 50 N m carries it by its top face (tool axis along
    gravity: no torque); one of 500 N carries it by none, and the plan names robot, block,
    need and payload."""
    a, m, tool_mass, depth = 0.4, 50.0, 3.0, 0.2
    ground = box_block("ground", (1, 1, 0.1), (0, 0, -0.05), density=2000, support=True)
    block = box_block("b", (a, 0.3, 0.2), (0, 0, 0.1), mass=m)
    scene_path = write(tmp_path, "one.json", scene_to_dict(make_scene("one", [ground, block])))

    def plan(force, torque):
        cell = {"robots": [{"name": "r", "base": [3.0, 0.0, 0.1], "reach": 4.0,
                            "payload_force": force, "payload_torque": torque,
                            "tool": {"box": [0.1, 0.1, depth], "tcp": [0, 0, depth],
                                     "mass": tool_mass}}]}
        capsys.readouterr()
        code = main(["plan", scene_path, "--cell", write(tmp_path, "c.json", cell), "--json"])
        return code, json.loads(capsys.readouterr().out)

    def xyz(v):
        return [v["x"], v["y"], v["z"]]

    code, result = plan(1000.0, 200.0)
    assert code == 0 and [(t["action"], t["block"]) for t in result["timeline"]] == [
        ("place", "b"), ("release", "b")]
    place = result["timeline"][0]
    assert xyz(place["grip"]["pose"]["position"]) == pytest.approx([a / 2, 0, 0.1])
    assert xyz(place["wrench_world"]["force"]) == pytest.approx([0, 0, m * G], abs=1e-9)
    assert xyz(place["wrench_world"]["torque"]) == pytest.approx([0, m * G * a / 2, 0],
                                                                 abs=1e-9)
    d = depth / 2 + 1e-3
    assert xyz(place["wrench_tool"]["force"]) == pytest.approx([(m + tool_mass) * G, 0, 0],
                                                               abs=1e-9)
    assert xyz(place["wrench_tool"]["torque"]) == pytest.approx(
        [0, m * G * a / 2 - tool_mass * G * d, 0], abs=1e-9)
    # 95.1 N m is beyond 50 N m: the top face, its torque nil
    code, result = plan(1000.0, 50.0)
    place = result["timeline"][0]
    assert code == 0 and xyz(place["grip"]["pose"]["position"]) == pytest.approx([0, 0, 0.2])
    assert xyz(place["wrench_tool"]["force"]) == pytest.approx([0, 0, -(m + tool_mass) * G],
                                                               abs=1e-9)
    assert xyz(place["wrench_tool"]["torque"]) == pytest.approx([0, 0, 0], abs=1e-9)
    # 520 N is beyond 500 N whatever the face
    code, result = plan(500.0, 200.0)
    assert code == 1 and not result["feasible"] and result["order"] == []
    need = f"carrying it needs |F| {(m + tool_mass) * G:.0f} N"
    assert "r cannot grip block b" in result["message"]
    assert f"{need}, |M| 0 N m with its gripper (payload 500 N, 200 N m)" in result["message"]
