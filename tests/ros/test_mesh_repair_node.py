"""The node repairs meshes as the CLI does (rbe_ros.geometry.repair) and logs each repair at
WARN naming the block: a design_file with an open voussoir, and an AssemblyState whose mesh
lacks two triangles, checked as the intact assembly."""
from __future__ import annotations

import json


from rbe_ros import generators as gen
from rbe_ros.io.messages import state_to_dict
from rbe_ros.io.scene_json import scene_to_dict
from rbe_ros.rbe.result import Status
from rbe_ros.ros.convert import dict_to_message

NAMESPACE = "mesh_repair"


class _Log:
    """Stands in for the node's logger: keeps the warnings."""

    def __init__(self):
        self.warnings = []

    def warning(self, text):
        self.warnings.append(text)

    def __getattr__(self, name):        # info, error, debug: ignored
        return lambda *args, **kwargs: None


def _open(state: dict, block: str) -> dict:
    raw = next(b for b in state["blocks"] if b["id"] == block)
    raw["mesh"]["triangles"] = raw["mesh"]["triangles"][2:]      # a quad face gone
    return state


def test_node_repairs_and_logs_open_meshes(make_node, tmp_path, monkeypatch):
    from rbe_msgs.msg import AssemblyState

    arch = gen.semicircular_arch(9)
    doc = scene_to_dict(arch)
    raw = next(b for b in doc["blocks"] if b["id"] == "v02")
    raw["mesh"]["faces"] = raw["mesh"]["faces"][1:]
    path = tmp_path / "design.json"
    path.write_text(json.dumps(doc))
    node = make_node()
    log = _Log()
    monkeypatch.setattr(node, "get_logger", lambda: log)
    node.design_message(str(path))
    assert log.warnings == [f"design_file {str(path)!r}: block 'v02': mesh repaired: filled "
                            "1 hole; replaced by its convex hull (volumes agree within 0.0001)"]
    state = dict_to_message(_open(state_to_dict(arch, "world"), "v05"), AssemblyState)
    check, _ = node.check(state, {"frame_id": "world", "stamp": {"sec": 1, "nanosec": 0}},
                          sequence=False)
    report = check.reports[0]
    assert report.status == Status.STABLE and report.num_blocks == 11
    assert log.warnings[1:] and set(log.warnings[1:]) == {
        "block 'v05': mesh repaired: filled 1 hole; replaced by its convex hull (volumes "
        "agree within 0.0001)"}
    assert len(report.interfaces) == 10          # 8 joints and 2 springings, as intact
