"""Declaring a node's parameter specs with rclpy, reading their values, proposed changes."""

from __future__ import annotations

import difflib
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, TypeVar

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.exceptions import ParameterException, ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter

from estimation_nodes.nodes.rclpy_internals import parameter_overrides
from estimation_nodes.params.specs import NODE_SPECS, UNSET, ParamSpec

Settings = TypeVar("Settings")


class ConfigurationError(Exception):
    """A parameter is invalid at start-up: the node cannot run."""


_TYPES_WITHOUT_DEFAULT = {
    "string_array": Parameter.Type.STRING_ARRAY,
    "double_array": Parameter.Type.DOUBLE_ARRAY,
}


def _descriptor(spec: ParamSpec) -> ParameterDescriptor:
    descriptor = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.min_value is not None and spec.max_value is not None:
        if isinstance(spec.default, int):
            descriptor.integer_range = [
                IntegerRange(from_value=int(spec.min_value), to_value=int(spec.max_value))
            ]
        else:
            descriptor.floating_point_range = [
                FloatingPointRange(from_value=spec.min_value, to_value=spec.max_value)
            ]
    return descriptor


def declare_parameters(node: Node, specs: Iterable[ParamSpec]) -> None:
    """Declare each spec with its description; a wrong type or range is a ConfigurationError."""
    for spec in specs:
        value = _TYPES_WITHOUT_DEFAULT[spec.type_name] if spec.default is UNSET else spec.default
        try:
            node.declare_parameter(spec.name, value, _descriptor(spec))
        except (ParameterException, TypeError, ValueError) as error:
            raise ConfigurationError(f"{spec.name}: {error}") from None


def parameter_values(node: Node, specs: Iterable[ParamSpec]) -> dict[str, Any]:
    """Current values by name; UNSET for a parameter declared without a value."""
    values: dict[str, Any] = {}
    for spec in specs:
        try:
            values[spec.name] = node.get_parameter(spec.name).value
        except ParameterUninitializedException:
            values[spec.name] = UNSET
    return values


def overlay(values: dict[str, Any], changes: Sequence[Parameter]) -> dict[str, Any]:
    """The values a set of proposed changes would give, without applying them."""
    merged = dict(values)
    for change in changes:
        merged[change.name] = UNSET if change.type_ == Parameter.Type.NOT_SET else change.value
    return merged


def rejection(reason: str) -> SetParametersResult:
    return SetParametersResult(successful=False, reason=reason)


def declare_and_build(
    node: Node, specs: Sequence[ParamSpec], build: Callable[[Mapping[str, Any]], Settings]
) -> tuple[dict[str, Any], Settings]:
    """Declare ``specs`` on ``node``, read their values and build the node's settings.

    Returns the values and the settings; a bad value is a ConfigurationError
    whose message names the parameter.
    """
    declare_parameters(node, specs)
    warn_unknown_parameters(node)
    values = parameter_values(node, specs)
    try:
        return values, build(values)
    except ValueError as error:
        raise ConfigurationError(str(error)) from None


#: Parameters every rclpy node declares itself.
RCLPY_PARAMETERS = ("use_sim_time", "start_type_description_service")


def warn_unknown_parameters(node: Node) -> list[str]:
    """Warn once of each given parameter that no node of this package declares.

    A name another node of the package takes (``world`` given to the commander
    by a shared ``/**`` section) is no mistake; a name none takes is, most
    likely, a misspelling: the warning names the closest known one.
    """
    known = {spec.name for specs in NODE_SPECS.values() for spec in specs}
    known.update(RCLPY_PARAMETERS)
    unknown = sorted(set(parameter_overrides(node)) - known)
    for name in unknown:
        closest = difflib.get_close_matches(name, sorted(known), n=1)
        hint = f"; did you mean '{closest[0]}'?" if closest else ""
        node.get_logger().warning(
            f"unknown parameter '{name}' ignored: no node of estimation_nodes has it{hint}")
    return unknown
