"""The one ROS parameter adapter of the ecahd_ros nodes (Nav2's ``ParameterHandler`` style):
each node lists its parameters once as ``ParamSpec(name, default, description)``, declares them
with a ParameterDescriptor, and reads them into a frozen dataclass whose ``__post_init__``
validates the values (raising EcahdError that names the parameter). The core then gets a plain
dataclass and never sees rclpy.

Parameters are read-only: they configure the node at start-up (``--ros-args -p name:=value`` or a
YAML file). Float parameters accept integer overrides (``-p max_v:=1``).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import TypeVar

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node

from ecahd_core.errors import EcahdError

T = TypeVar("T")


@dataclass(frozen=True)
class ParamSpec:
    """One ROS parameter: its name, default (whose type is the parameter's type) and description
    (units in brackets, as in the README table)."""

    name: str
    default: object
    description: str


def declare_parameters(node: Node, specs: Sequence[ParamSpec]) -> None:
    """Declare every parameter once, read-only, with its description. Floats are declared with
    dynamic typing so an integer override is accepted (and checked in :func:`read_parameters`)."""
    for spec in specs:
        node.declare_parameter(spec.name, spec.default, ParameterDescriptor(
            description=spec.description, read_only=True,
            dynamic_typing=isinstance(spec.default, float)))


def read_parameters(node: Node, specs: Sequence[ParamSpec], cls: type[T]) -> T:
    """Read the declared parameters into ``cls`` (a frozen dataclass with one field per spec).
    Raises EcahdError naming the parameter when a value has the wrong type or is not finite;
    ``cls.__post_init__`` checks the ranges."""
    names = {f.name for f in fields(cls)}
    values = {}
    for spec in specs:
        if spec.name not in names:
            raise EcahdError(f"parameter {spec.name} has no field in {cls.__name__}")
        value = node.get_parameter(spec.name).value
        if isinstance(spec.default, float):
            if (isinstance(value, bool) or not isinstance(value, (int, float))
                    or not math.isfinite(value)):
                raise EcahdError(f"parameter {spec.name} must be a finite number, got {value!r}")
            value = float(value)
        elif isinstance(spec.default, bool):
            if not isinstance(value, bool):
                raise EcahdError(f"parameter {spec.name} must be a bool, got {value!r}")
        elif isinstance(spec.default, int):
            if isinstance(value, bool) or not isinstance(value, int):
                raise EcahdError(f"parameter {spec.name} must be an integer, got {value!r}")
        values[spec.name] = value
    return cls(**values)


def require(condition: bool, name: str, value, what: str) -> None:
    """Raise EcahdError('parameter <name> must be <what>, got <value>') unless ``condition``."""
    if not condition:
        raise EcahdError(f"parameter {name} must be {what}, got {value!r}")


def require_positive(params, *names: str) -> None:
    """Each named field of ``params`` must be > 0."""
    for name in names:
        value = getattr(params, name)
        require(value > 0, name, value, "> 0")


def require_non_negative(params, *names: str) -> None:
    """Each named field of ``params`` must be >= 0."""
    for name in names:
        value = getattr(params, name)
        require(value >= 0, name, value, ">= 0")


def robot_spec(robot: str, footprint: str) -> str:
    """The footprint spec for ``make_footprint``: the Nav2 string when set, else the preset."""
    return footprint.strip() or robot
