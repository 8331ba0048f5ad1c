"""The one option specification: every check option round-trips through the CLI, the node's
parameters, the options stored in bags and live replay's node parameters."""
from __future__ import annotations

import math

import pytest
from rcl_interfaces.msg import ParameterType
from rclpy.parameter import Parameter

from rbe_ros.analysis.option_spec import (BY_PARAM, OPTIONS, from_json, from_outer,
                                          node_parameters, to_json)
from rbe_ros.analysis.options import CheckOptions
from rbe_ros.cli import _options, build_parser
from rbe_ros.ros.node import PARAMETERS, RbeNode

NAMESPACE = "/rbe_option_spec_test"


def probe(option):
    """An outer value of ``option`` other than its default, inside its range."""
    default = option.default
    if option.kind is bool:
        return not default
    if option.kind is str:
        return next(c for c in option.choices if c != default)
    value = option.kind((option.low + option.high) / 2) if option.high <= 1000 else \
        option.kind(default * 2 or 1)
    assert value != default and option.problem(value) is None
    return value


SETTABLE = [o for o in OPTIONS if o.flag and o.param]


def test_every_option_with_a_flag_has_a_parameter_and_the_other_way_round():
    assert {o.path for o in OPTIONS if o.flag} == {o.path for o in OPTIONS if o.param}
    # stored in bags: all but the limits of the machine that checks and the second opinion
    assert {o.path for o in OPTIONS if not o.stored} == {"solve.time_limit",
                                                          "limits.max_blocks",
                                                          "second_opinion"}


@pytest.mark.parametrize("option", SETTABLE, ids=lambda o: o.path)
def test_an_option_round_trips_through_cli_node_bag_and_live_replay(option, rclpy_context):
    value = probe(option)
    core = option.inner(value)
    # CLI: the flag (a bool on by default: its --no- flag)
    argv = ["check", "scene.json"] + ([option.flag] if option.kind is bool
                                      else [option.flag, str(value)])
    from_cli = _options(build_parser().parse_args(argv))
    assert option.get(from_cli) == core
    assert from_cli == option.set(CheckOptions(), core)       # nothing else changed
    # node: the parameter, typed and ranged by its descriptor
    default, descriptor = PARAMETERS[option.param]
    assert default == option.default
    assert descriptor.type == {float: ParameterType.PARAMETER_DOUBLE,
                               int: ParameterType.PARAMETER_INTEGER,
                               bool: ParameterType.PARAMETER_BOOL,
                               str: ParameterType.PARAMETER_STRING}[option.kind]
    node = RbeNode(namespace=NAMESPACE, context=rclpy_context,
                   parameter_overrides=[Parameter(option.param, value=value)])
    try:
        from_node = node.check_options()
        refused = node.set_parameters([Parameter(option.param, value=_outside(option))])[0]
        assert not refused.successful       # by the range check, or by rclpy for a type
        assert option.kind is bool or option.param in refused.reason
    finally:
        node.destroy_node()
    assert from_node == from_cli
    # bag: stored and read back (the limits of the checking machine are not stored)
    restored = from_json(to_json(from_cli))
    assert restored == (from_cli if option.stored else CheckOptions())
    # live replay: the node parameters of the bag's options
    parameters = node_parameters(restored)
    assert parameters[option.param] == (value if option.stored else option.default)
    assert from_outer({BY_PARAM[k]: v for k, v in parameters.items()}) == restored


def _outside(option):
    """An outer value the parameter refuses."""
    if option.kind is str:
        return "no-such-choice"
    if option.kind is bool:
        return 1
    return option.kind(option.high * 2 + 1)


def test_live_replay_refuses_options_the_node_cannot_be_set_to():
    fixed = [o for o in OPTIONS if o.param is None]
    assert {o.path for o in fixed} >= {"solve.weights.tension", "solve.allow_tension"}
    for option in fixed:
        value = option.get(CheckOptions())
        changed = option.set(CheckOptions(), not value if option.kind is bool else value + 1)
        assert from_json(to_json(changed)) == changed        # stored all the same
        with pytest.raises(ValueError, match=option.path):
            node_parameters(changed)


def test_zero_stands_for_none_in_flags_and_parameters():
    threshold, limit = BY_PARAM["friction_threshold"], BY_PARAM["check_time_limit"]
    assert threshold.inner(0.0) is None and limit.inner(0.0) == math.inf
    assert threshold.outer(CheckOptions()) == 0.0 and limit.outer(CheckOptions()) == 0.0
    assert from_outer({threshold: 0.3}).threshold == 0.3
