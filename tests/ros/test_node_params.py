"""RbeNode in-process (not spun): parameters, their mapping to CheckOptions, bag path."""
from __future__ import annotations

import math

import pytest
from rcl_interfaces.msg import ParameterType
from rclpy.exceptions import InvalidParameterValueException
from rclpy.parameter import Parameter
from scipy.spatial.transform import Rotation

from rbe_ros.analysis.pipeline import check_scene
from rbe_ros.rbe.result import Status
from rbe_ros.scene import box_block, make_scene

NAMESPACE = "/rbe_unit_test"   # apart from the node process of test_node.py


def slope(tan: float):
    """A box resting on a support slab tilted by atan(tan): it needs |V|/N = tan."""
    q = Rotation.from_euler("y", math.atan(tan)).as_quat()
    centre = Rotation.from_quat(q).apply([0, 0, 0.6])
    return make_scene("slope", [box_block("ground", (4, 4, 0.2), (0, 0, 0), q, support=True,
                                          density=2000),
                                box_block("box", (1, 1, 1), centre, q, density=2000)])


def test_declared_parameters_and_defaults(make_node):
    node = make_node()
    expected = {"friction_coefficient": 0.6, "friction_threshold": 0.0, "objective": "qp",
                "friction_model": "net", "friction_cone": "soc", "tension_tolerance": 1e-5,
                "mcap_path": "", "frame_id": "world"}
    assert {k: node.get_parameter(k).value for k in expected} == expected
    for name in expected:
        d = node.describe_parameter(name)
        assert d.description
    mu = node.describe_parameter("friction_coefficient")
    assert mu.type == ParameterType.PARAMETER_DOUBLE
    assert (mu.floating_point_range[0].from_value, mu.floating_point_range[0].to_value) == (0, 10)
    assert "pyramid8-outer" in node.describe_parameter("friction_cone").additional_constraints
    assert node.describe_parameter("mcap_path").read_only

    opts = node.check_options()
    assert (opts.solve.mu, opts.mu_threshold, opts.tension_tol) == (0.6, None, 1e-5)
    assert (opts.solve.objective, opts.solve.friction, opts.solve.cone) == ("qp", "net", "soc")


def test_set_parameters_validated_and_used(make_node):
    node = make_node(friction_coefficient=0.4)
    assert check_scene(slope(0.5), node.check_options()).status == Status.FRICTION_EXCEEDED

    results = node.set_parameters([Parameter("friction_coefficient", value=0.6)])
    assert results[0].successful
    assert check_scene(slope(0.5), node.check_options()).status == Status.STABLE

    assert node.set_parameters([Parameter("friction_threshold", value=0.45)])[0].successful
    opts = node.check_options()
    assert opts.mu_threshold == 0.45 and opts.threshold == 0.45
    assert check_scene(slope(0.5), opts).status == Status.FRICTION_EXCEEDED

    for name, value, reason in [("objective", "simplex", "qp, lp"),
                                ("friction_model", "glue", "net, plus"),
                                ("friction_cone", "cube", "soc, pyramid8"),
                                ("friction_coefficient", 0.0, "(0, 10]"),
                                ("friction_coefficient", math.nan, ""),
                                ("tension_tolerance", 2.0, ""),
                                ("friction_threshold", -0.1, "")]:
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful and reason in result.reason, (name, result.reason)
    assert node.get_parameter("objective").value == "qp"
    assert node.set_parameters([Parameter("friction_cone", value="pyramid4"),
                                Parameter("objective", value="lp")])[0].successful
    assert (node.check_options().solve.cone, node.check_options().solve.objective) == \
        ("pyramid4", "lp")


def test_bad_override_is_refused_at_start(make_node):
    with pytest.raises(InvalidParameterValueException):
        make_node(friction_cone="cube")


def test_existing_bag_path_gets_a_suffix(make_node, tmp_path):
    target = tmp_path / "bag"
    target.mkdir()
    (target / "keep.txt").write_text("old")
    node = make_node(mcap_path=str(target))
    assert node.bag_path.parent == tmp_path and node.bag_path.name.startswith("bag_")
    assert (node.bag_path / "metadata.yaml").is_file()
    assert (target / "keep.txt").read_text() == "old"
    second = make_node(mcap_path=str(target))
    assert second.bag_path != node.bag_path and second.bag_path.name.startswith("bag_")
    node.destroy_node()
    assert (node.bag_path / f"{node.bag_path.name}_0.mcap").read_bytes().endswith(b"MCAP0\r\n")


def test_unexpected_errors_become_solver_failed_reports(make_node, tmp_path, monkeypatch):
    from rbe_msgs.msg import AssemblyState, StabilityReport
    from rbe_msgs.srv import CheckAssembly

    from rbe_client import stacked_boxes
    from rbe_ros.analysis import pipeline
    from rbe_ros.io import bag, messages
    from rbe_ros.ros.convert import dict_to_message

    def boom(*_args, **_kwargs):
        raise RuntimeError("boom")

    # the node's one dispatch (shared with replay) calls these
    monkeypatch.setattr(pipeline, "check_scene", boom)
    monkeypatch.setattr(pipeline, "check_sequence", boom)
    node = make_node(mcap_path=str(tmp_path / "bag"), frame_id="site")
    state = dict_to_message(messages.state_to_dict(stacked_boxes(0.45), "", 42), AssemblyState)
    response = node._on_check(CheckAssembly.Request(assembly=state), CheckAssembly.Response())
    r = response.report
    assert r.status == StabilityReport.SOLVER_FAILED and not r.stable
    assert "RuntimeError: boom" in r.message
    assert r.header.frame_id == "site" and r.header.stamp.nanosec == 42
    state.sequence = ["a", "b"]
    node.check_state(state)          # the per-step path fails the same way, node unharmed
    node.destroy_node()
    recorded = list(bag.read_bag(tmp_path / "bag"))
    settings, recorded = recorded[0], recorded[1:]       # the node's settings at the start
    assert settings.topic == "/rbe_unit_test/rbe_node/settings"
    assert [m.topic for m in recorded] == ["/rbe_unit_test/rbe_node/assembly",
                                           "/rbe_unit_test/rbe_node/report",
                                           "/rbe_unit_test/rbe_node/markers"] * 2
    assert [m.data["status"] for m in recorded[1::3]] == [StabilityReport.SOLVER_FAILED] * 2


def test_contact_parameters_reach_the_detection(make_node):
    """A box floating 5 mm (0.5% of its size) above the slab: no contact at the default
    distance tolerance (0.1%), resting on the slab at 1%."""
    scene = make_scene("gap", [box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True,
                                         density=2000),
                               box_block("box", (1, 1, 1), (0, 0, 0.505), density=2000)])
    node = make_node()
    assert node.check_options().contact.distance_tol == 1e-3
    assert check_scene(scene, node.check_options()).status == Status.INFEASIBLE
    node.set_parameters([Parameter("contact_distance_tolerance", value=0.01)])
    report = check_scene(scene, node.check_options())
    assert report.status == Status.STABLE
    assert report.interfaces[0].normal_resultant == pytest.approx(2000 * 9.81, rel=1e-6)
    bad = node.set_parameters([Parameter("contact_min_width", value=-0.1)])[0]
    assert not bad.successful and "contact_min_width" in bad.reason


def test_pose_uncertainty_parameters_reach_the_detection(make_node):
    """The same box 5 mm above the slab, with every pose known to within 3 mm: the two
    allowances (3 mm each) and the 1 mm tolerance make it a contact, on the mid-plane."""
    scene = make_scene("gap", [box_block("ground", (4, 4, 0.2), (0, 0, -0.1), support=True,
                                         density=2000),
                               box_block("box", (1, 1, 1), (0, 0, 0.505), density=2000)])
    node = make_node(pose_uncertainty_m=0.003, pose_uncertainty_deg=0.0)
    contact = node.check_options().contact
    assert (contact.pose_uncertainty_m, contact.pose_uncertainty_deg) == (0.003, 0.0)
    report = check_scene(scene, node.check_options())
    assert report.status == Status.STABLE and not report.near_contacts
    assert report.interfaces[0].centre_of_pressure[2] == pytest.approx(0.0025, abs=1e-12)
    bad = node.set_parameters([Parameter("pose_uncertainty_deg", value=-1.0)])[0]
    assert not bad.successful and "pose_uncertainty_deg" in bad.reason


def test_record_markers_false_keeps_a_lean_bag(make_node, tmp_path):
    from rbe_msgs.msg import AssemblyState
    from rbe_msgs.srv import CheckAssembly

    from rbe_client import stacked_boxes
    from rbe_ros.io import bag, messages
    from rbe_ros.ros.convert import dict_to_message

    node = make_node(mcap_path=str(tmp_path / "bag"), record_markers=False)
    state = dict_to_message(messages.state_to_dict(stacked_boxes(0.45), "", 1), AssemblyState)
    assert node._on_check(CheckAssembly.Request(assembly=state),
                          CheckAssembly.Response()).report.stable
    node.destroy_node()
    assert [m.topic for m in bag.read_bag(tmp_path / "bag")] == [
        "/rbe_unit_test/rbe_node/settings", "/rbe_unit_test/rbe_node/assembly",
        "/rbe_unit_test/rbe_node/report"]


def test_log_unstable_at_warn_changes_at_info_and_a_summary_not_a_line_per_report(
        make_node, monkeypatch):
    from rbe_msgs.msg import AssemblyState

    from rbe_client import stacked_boxes
    from rbe_ros.io import messages
    from rbe_ros.ros import node as node_module
    from rbe_ros.ros.convert import dict_to_message

    lines: list[tuple[str, str]] = []

    class Capture:
        def __getattr__(self, level):
            return lambda text, **_kw: lines.append((level, text))

    node = make_node()
    monkeypatch.setattr(node, "get_logger", lambda: Capture())
    assert node.set_parameters([Parameter("friction_coefficient", value=0.5)])[0].successful
    assert lines == [("info", "parameters set: friction_coefficient = 0.5")]
    lines.clear()
    # 5 standing stacks, then 5 with the top box's centre beyond the edge (0.6 > 0.5)
    for k, shift in enumerate([0.1] * 5 + [0.6] * 5):
        node.check_state(dict_to_message(messages.state_to_dict(stacked_boxes(shift), "", k),
                                         AssemblyState))
    # the first report is summed up at once, then nothing until LOG_SUMMARY_S has passed;
    # the unstable verdict once (unchanged for the next four)
    assert [level for level, _ in lines] == ["info", "warning"]
    assert lines[0][1].startswith("1 reports in") and "1 STABLE" in lines[0][1]
    assert "TENSION_REQUIRED" in lines[1][1]
    monkeypatch.setattr(node, "_log_since", node._log_since - node_module.LOG_SUMMARY_S)
    node.check_state(dict_to_message(messages.state_to_dict(stacked_boxes(0.1), "", 10),
                                     AssemblyState))
    assert lines[2][0] == "info" and "5 STABLE, 5 TENSION_REQUIRED" in lines[2][1] \
        and lines[2][1].startswith("10 reports in"), lines


def test_integers_accepted_for_every_float_parameter(make_node):
    """``-p max_bag_duration_s:=120`` (an integer on the launch line) starts the node with
    120.0, for every float parameter alike (was: FATAL, the node dead at start)."""
    from rbe_ros.ros.node import PARAMETERS

    floats = {name: d.floating_point_range[0] for name, (_, d) in PARAMETERS.items()
              if d.type == ParameterType.PARAMETER_DOUBLE}
    assert {"max_bag_duration_s", "friction_coefficient", "marker_rate_hz"} <= set(floats)
    given = {name: 120 if name == "max_bag_duration_s" else 1 for name in floats}
    node = make_node(**given)
    for name, value in given.items():
        p = node.get_parameter(name)
        assert p.type_ == Parameter.Type.DOUBLE and p.value == float(value), name
    assert node.get_parameter("max_bag_duration_s").value == 120.0
