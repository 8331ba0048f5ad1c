"""Starting rbe_node as a cell does: config/rbe_node.yaml through --params-file, and a clean
one-line exit for a bag that cannot be created."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from rbe_ros.ros.live import NodeProcess
from rbe_ros.ros.node import PARAMETERS, RbeNode

CONFIG = Path(__file__).resolve().parents[2] / "config" / "rbe_node.yaml"


def test_the_documented_parameter_file_lists_every_parameter_at_its_default():
    values = yaml.safe_load(CONFIG.read_text())["/**"]["ros__parameters"]
    assert values == {name: default for name, (default, _) in PARAMETERS.items()}
    text = CONFIG.read_text()
    for name, (_, descriptor) in PARAMETERS.items():       # each documented above its line
        first_words = " ".join(descriptor.description.split()[:4])
        assert first_words in " ".join(text.split()), name


def test_the_node_takes_its_parameters_from_the_file(rclpy_context, tmp_path):
    values = yaml.safe_load(CONFIG.read_text())
    values["/**"]["ros__parameters"].update(friction_coefficient=0.45, contact_min_width=0.002,
                                            full_solve=True, friction_cone="pyramid4")
    path = tmp_path / "cell.yaml"
    path.write_text(yaml.safe_dump(values))
    node = RbeNode(namespace="/rbe_config_test", context=rclpy_context,
                   cli_args=["--ros-args", "--params-file", str(path)])
    try:
        options = node.check_options()
    finally:
        node.destroy_node()
    assert options.solve.mu == 0.45 and options.contact.min_width == 0.002
    assert options.full_solve and options.solve.cone == "pyramid4"
    assert options.solve.objective == "qp" and options.holds.max_checks == 40   # the file's


@pytest.mark.parametrize("path", ["/proc/no_such_dir/bag", "/dev/null/bag"])
def test_a_bag_that_cannot_be_created_ends_the_node_with_one_line(path, tmp_path):
    proc = NodeProcess(["-p", f"mcap_path:={path}"], tmp_path / "node.log")
    try:
        code = proc.proc.wait(timeout=30)
    finally:
        proc.stop()
    output = proc.output()
    assert code == 2
    assert "Traceback" not in output
    errors = [line for line in output.splitlines() if "FATAL" in line]
    assert len(errors) == 1 and f"mcap_path '{path}': cannot create the bag" in errors[0]
