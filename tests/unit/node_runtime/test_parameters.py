"""The loop nodes' parameters declared as data: the docs' reference equals the declarations, and
one declaration checks a value at start (InputError) and at a set (refused with the reason),
on a real node of either backend."""

from __future__ import annotations

import dataclasses
import math
from typing import Literal

import pytest

from stillframe.errors import InputError
from stillframe.locations import REPO_ROOT
from stillframe.middleware import api
from stillframe.middleware.params import Parameter, Range
from stillframe.node_runtime.declarations import (
    NODE_PARAMETERS,
    REFERENCE_MARKERS,
    ControllerParameterValues,
    NoiseParameterValues,
    with_reference,
)
from stillframe.node_runtime.parameters import (
    NodeParameters,
    between,
    declare,
    param,
    positive,
    set_check,
)


def test_the_docs_reference_is_generated_from_the_declarations() -> None:
    """docs/nodes.md holds the table :func:`reference` writes, and every declared parameter is
    in it once per meaning (regenerate: ``python -m stillframe.node_runtime.declarations``)."""
    page = (REPO_ROOT / "docs" / "nodes.md").read_text()
    assert all(marker in page for marker in REFERENCE_MARKERS)
    assert with_reference(page) == page
    start, end = (page.index(m) for m in REFERENCE_MARKERS)
    table = page[start:end]
    declared = {s.name for classes in NODE_PARAMETERS.values() for c in classes
                for s in c.specs()}
    assert {row.split("`")[1] for row in table.splitlines()[3:]} == declared
    assert len(declared) == 32      # changes only with a declaration added or removed


@dataclasses.dataclass(frozen=True)
class Example(NodeParameters):
    rate: float = param(2.0, positive, unit="Hz", doc="a rate")
    share: float = param(0.5, between(0.0, 1.0, high_open=True), dynamic=True, doc="a share")
    mode: Literal["a", "b"] = param("a", doc="a choice")
    gains: list[float] = param([1.0, 2.0], positive, dynamic=True, doc="gains")


class Node:
    """What :func:`declare` needs of a node: the override given, else the default."""

    def __init__(self, **given: object) -> None:
        self.given = given

    def declare_parameter(self, name: str, default: object, read_only: bool = False, *,
                          descriptor: object = None) -> Parameter:
        return Parameter(name, self.given.get(name, default))


def test_declare_checks_every_value_by_its_declaration() -> None:
    values = declare(Node(rate=4), Example)
    assert values == Example(4.0, 0.5, "a", [1.0, 2.0])     # an integer widens to a double
    for given, text in ((dict(rate=0.0), "'rate': must be > 0 (got 0.0)"),
                        (dict(rate=math.inf), "'rate': must be finite"),
                        (dict(share=1.0), "'share': must lie in [0, 1) (got 1.0)"),
                        (dict(mode="c"), "'mode': expected one of a, b, got 'c'"),
                        (dict(gains=[1.0, -2.0]), "'gains': must be > 0"),
                        (dict(gains=["x"]), "'gains': expected a list of double"),
                        (dict(mode=3), "'mode': expected string, got 3")):
        with pytest.raises(InputError, match=text.replace("[", r"\[").replace(")", r"\)")
                           .replace("(", r"\(")):
            declare(Node(**given), Example)


def test_a_set_is_checked_by_the_same_declaration() -> None:
    check = set_check(Example)
    assert check([Parameter("share", 0.25), Parameter("gains", [3.0])]).successful
    refused = [check([Parameter(name, value)]) for name, value in (
        ("share", 1.5), ("gains", [0.0]), ("rate", 3.0), ("use_sim_time", True))]
    assert [r.successful for r in refused] == [False] * 4
    assert [r.reason for r in refused] == [
        "share: must lie in [0, 1) (got 1.5)", "gains: must be > 0 (got [0.0])",
        "parameter 'rate' cannot change while the node runs",
        "parameter 'use_sim_time' cannot change while the node runs"]


BACKENDS = ["dds", pytest.param("rclpy", marks=pytest.mark.skipif(
    not api.has_rclpy(), reason="rclpy not installed"))]


@pytest.mark.processes
@pytest.mark.parametrize("backend", BACKENDS)
def test_a_real_node_declares_checks_and_refuses_by_the_declarations(
        backend: str, ros_domain: int) -> None:
    """On a real node of each backend: the controller's parameters declared with the scene's
    defaults, read-only ones refused by the middleware, a dynamic one by its declaration."""
    node = api.create_node("controller_node", namespace="/frame",
                           argv=["x", "--ros-args", "-p", "command_limit:=0.5"], backend=backend)
    try:
        scene = type("Scene", (), {"controller": type("C", (), {"limit": None})()})()
        values = declare(node, ControllerParameterValues, scene)
        assert values.command_limit == 0.5 and values.enabled is True
        node.add_on_set_parameters_callback(set_check(ControllerParameterValues))
        params = node._params if backend == "dds" else None
        if params is not None:
            assert not params.set("command_limit", -1.0).successful
            assert params.set("command_limit", 0.25).successful
            assert "read-only" in params.set("estimate_writer", "x").reason
        else:
            from rclpy.parameter import Parameter as RclpyParameter

            results = node._node.set_parameters([
                RclpyParameter("command_limit", value=-1.0),
                RclpyParameter("command_limit", value=0.25),
                RclpyParameter("estimate_writer", value="x")])
            assert [r.successful for r in results] == [False, True, False]
            # rclpy holds a set to the descriptor's range before any callback, in its words
            assert results[0].reason == ("Parameter command_limit out of range Min: 0.0, "
                                         "Max: inf, value: -1.0")
            assert "read-only" in results[2].reason
        assert node.get_parameter("command_limit").value == 0.25
    finally:
        node.destroy_node()


def test_each_declaration_is_described_as_rclpy_describes_its_own() -> None:
    """The descriptor of every field of :class:`Example`: the doc with its unit, the closed range
    of a scalar number (step 0: any value), what a range cannot say in words (an open bound,
    the choices, a list's items), read-only unless set at run time."""
    described = {s.name: s.descriptor() for s in Example.specs()}
    rate, share, mode, gains = (described[n] for n in ("rate", "share", "mode", "gains"))
    assert (rate.description, rate.read_only, rate.range) == (
        "a rate; unit: Hz", True, Range(0, math.inf, 0))
    assert rate.additional_constraints == "> 0 (0 itself is refused; a range is closed); finite"
    assert (share.read_only, share.range) == (False, Range(0.0, 1.0, 0))
    assert share.additional_constraints.startswith("< 1 (1 itself is refused")
    assert (mode.range, mode.additional_constraints) == (None, "one of a, b")
    assert gains.range is None
    assert gains.additional_constraints == "> 0 (no range: a range holds a single number); finite"


@pytest.mark.processes
@pytest.mark.parametrize("backend", BACKENDS)
def test_a_real_node_describes_and_checks_start_values_by_the_declarations(
        backend: str, ros_domain: int) -> None:
    """The descriptor a real node of each backend answers on ``describe_parameters`` (rclpy's own
    ParameterService on rclpy: the independent side) carries the declaration's description,
    range and read-only flag; a start value outside the range is refused in the declaration's
    words on both (rclpy would refuse it in its own)."""
    scene = type("Scene", (), {"controller": type("C", (), {"limit": None})()})()
    node = api.create_node("controller_node", namespace="/frame", argv=["x"], backend=backend)
    try:
        declare(node, ControllerParameterValues, scene)
        if backend == "dds":
            from stillframe.contract import messages
            from stillframe.middleware.param_messages import answer_describe

            request = messages.new("rcl_interfaces/srv/DescribeParameters_Request",
                                   names=["command_limit", "estimate_writer"])
            limit, writer = answer_describe(node._params, request).descriptors
        else:
            limit, writer = node._node.describe_parameters(["command_limit", "estimate_writer"])
        spec = next(s for s in ControllerParameterValues.specs() if s.name == "command_limit")
        assert limit.description == spec.descriptor().description
        assert "unit: N m or N" in limit.description and not limit.read_only
        assert [(r.from_value, r.to_value, r.step) for r in limit.floating_point_range] == [
            (0.0, math.inf, 0.0)]
        assert list(limit.integer_range) == [] and writer.read_only
    finally:
        node.destroy_node()
    node = api.create_node("controller_node", namespace="/frame",
                           argv=["x", "--ros-args", "-p", "command_limit:=-1.0"], backend=backend)
    try:
        with pytest.raises(InputError, match=r"'command_limit': must be >= 0 \(got -1.0\)"):
            declare(node, ControllerParameterValues, scene)
    finally:
        node.destroy_node()


def test_noise_defaults_come_from_the_scene() -> None:
    scene = type("Scene", (), {"estimator": type("E", (), {
        "process_noise_std": (0.1,) * 8, "measurement_noise_std": (0.2,) * 4})()})()
    values = declare(Node(), NoiseParameterValues, scene)
    assert values.process_noise_std == [0.1] * 8 and values.measurement_noise_std == [0.2] * 4
    with pytest.raises(InputError, match="expected 4 values"):
        declare(Node(measurement_noise_std=[0.2] * 3), NoiseParameterValues, scene)
