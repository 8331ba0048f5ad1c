"""The node's ``second_opinion`` parameter: the second opinion's line ends the report's message
(StabilityReport has no field for it) and is logged; not installed, the message says so and
how to install it, and the node answers as before."""
from __future__ import annotations

NAMESPACE = "/rbe_second_opinion_test"


def test_second_opinion_not_installed_is_said_in_the_report(make_node, tmp_path, monkeypatch):
    from rbe_msgs.msg import AssemblyState
    from rbe_msgs.srv import CheckAssembly

    from rbe_client import stacked_boxes
    from rbe_ros.io import lmgc90, messages
    from rbe_ros.ros.convert import dict_to_message

    monkeypatch.setenv(lmgc90.VENV_ENV, str(tmp_path / "no-venv"))
    node = make_node(second_opinion="lmgc90")
    assert node.check_options().second_opinion == "lmgc90"
    state = dict_to_message(messages.state_to_dict(stacked_boxes(0.45), "", 1), AssemblyState)
    report = node._on_check(CheckAssembly.Request(assembly=state),
                            CheckAssembly.Response()).report
    assert report.stable and report.message.startswith("stable: ")
    assert report.message.endswith(f"| second opinion unavailable: LMGC90 is not installed in"
                                   f" {tmp_path / 'no-venv'}: run `make lmgc90` in the rbe_ros"
                                   f" source tree (about 1 GB, a few minutes), or set"
                                   f" {lmgc90.VENV_ENV} to the venv it made")
    plain = make_node()
    assert "second opinion" not in plain._on_check(CheckAssembly.Request(assembly=state),
                                                   CheckAssembly.Response()).report.message
