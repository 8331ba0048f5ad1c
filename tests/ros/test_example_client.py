"""examples/node_client.py, the README's plain rclpy client, against a running rbe_node: a
planned 7-voussoir arch executed from poses step by step, bad poses and bad ~/plan goals
answered with their reasons, a ~/plan of the design, and the node's bag replayed."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from rbe_ros.cli import main
from rbe_ros.ros.live import NodeProcess

pytestmark = pytest.mark.long      # a node, 7 poses, 3 plans and a replay: about a minute
CLIENT = Path(__file__).resolve().parents[2] / "examples" / "node_client.py"


def test_the_example_client_drives_a_planned_arch(tmp_path):
    """Every step stands as built with the plan's holds, every bad input gets its reason."""
    arch, planned, bag = tmp_path / "arch.json", tmp_path / "planned.json", tmp_path / "run"
    assert main(["generate", "semicircular-arch", "-p", "n=7", "-o", str(arch)]) == 0
    assert main(["plan", str(arch), "--max-held", "2", "-o", str(planned)]) == 0
    node = NodeProcess(["-p", f"design_file:={planned}", "-p", f"mcap_path:={bag}"],
                       tmp_path / "node.log")
    try:
        out = subprocess.run([sys.executable, str(CLIENT), str(planned), "--timeout", "60"],
                             capture_output=True, text=True, timeout=600)
    finally:
        assert node.stop() == 0
    lines = out.stdout.splitlines()
    assert out.returncode == 0 and json.loads(lines[-1]) == {"unanswered": 0}, out.stdout
    # every step of the plan stands at the design poses, the look-ahead finds nothing failing
    executions = [x for x in lines if x.startswith("    execution: active True")]
    assert len(executions) == 7
    assert all("as built (the plan's holds) STABLE" in x and "first failing none" in x
               for x in executions)
    assert "step 7/7" in executions[-1]
    text = out.stdout
    assert "an unknown block: answered" in text and "INVALID_INPUT" in text
    assert "not in the design" in text and "'no_such_block'" in text
    assert "orientation must be finite, got NaN or infinity" in text
    assert "a malformed cell" in text and "cell: YAML does not parse" in text
    assert "sequence names block 'no_such_block', which is not in the scene" in text
    assert "order ['v00', 'v06', 'v01', 'v05', 'v02', 'v04', 'v03']" in text
    assert main(["replay", str(bag), "--compare", "-o", str(tmp_path / "replayed")]) == 0
