"""The one ROS parameter adapter of the ecahd_ros nodes (Nav2's ``ParameterHandler`` style):
each node lists its parameters once as ``ParamSpec(name, default, description)``, declares them
with a ParameterDescriptor, and reads them into a frozen dataclass whose ``__post_init__``
validates the values (raising EcahdError that names the parameter). The core then gets a plain
dataclass and never sees rclpy.

Parameters configure the node at start-up (``--ros-args -p name:=value`` or a YAML file). Most
are read-only: ROS rejects a change with "read-only parameter". The few a node lists as dynamic
(e.g. local_refiner's velocity limits) can be set at run time (``ros2 param set``): the new value
is validated with the others (the same dataclass) and applied, or the change is rejected with the
validation error as its reason, never silently ignored. Float parameters accept integer overrides
(``-p max_v:=1``). :data:`SHARED` is the one home of the parameters several nodes declare.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, fields, replace
from typing import TypeVar

from rcl_interfaces.msg import ParameterDescriptor, SetParametersResult
from rclpy.node import Node

from ecahd_core.errors import EcahdError
from ecahd_core.frames import TRANSFORM_TOLERANCE
from ecahd_core.maps import DEFAULT_MAP

T = TypeVar("T")


@dataclass(frozen=True)
class ParamSpec:
    """One ROS parameter: its name, default (whose type is the parameter's type) and description
    (units in brackets, as in the README table)."""

    name: str
    default: object
    description: str


def parameters_dataclass(specs: Sequence[ParamSpec]):
    """Class decorator: ``cls`` as a frozen, keyword-only dataclass with one field per spec of
    ``specs``, in their order, each typed as its default. The fields are declared nowhere else
    (one home: the ParamSpec list); the class adds ``__post_init__`` validation and the
    methods that hand the core its configs."""
    def wrap(cls):
        own = cls.__dict__.get("__annotations__", {})
        if own:
            raise EcahdError(f"{cls.__name__}: its fields come from its ParamSpec list; remove "
                             f"the annotations {sorted(own)}")
        cls.__annotations__ = {spec.name: type(spec.default).__name__ for spec in specs}
        return dataclass(frozen=True, kw_only=True)(cls)
    return wrap


def declare_parameters(node: Node, specs: Sequence[ParamSpec],
                       dynamic: Sequence[str] = ()) -> None:
    """Declare every parameter once with its description; read-only unless named in
    ``dynamic``. Floats are declared with dynamic typing so an integer override is accepted
    (and checked in :func:`read_parameters`)."""
    for spec in specs:
        node.declare_parameter(spec.name, spec.default, ParameterDescriptor(
            description=spec.description, read_only=spec.name not in dynamic,
            dynamic_typing=isinstance(spec.default, float)))


def _checked(spec: ParamSpec, value):
    """``value`` of ``spec``'s type (ints accepted for floats), else EcahdError."""
    if isinstance(spec.default, float):
        if (isinstance(value, bool) or not isinstance(value, (int, float))
                or not math.isfinite(value)):
            raise EcahdError(f"parameter {spec.name} must be a finite number, got {value!r}")
        return float(value)
    if isinstance(spec.default, bool):
        if not isinstance(value, bool):
            raise EcahdError(f"parameter {spec.name} must be a bool, got {value!r}")
    elif isinstance(spec.default, int):
        if isinstance(value, bool) or not isinstance(value, int):
            raise EcahdError(f"parameter {spec.name} must be an integer, got {value!r}")
    elif isinstance(spec.default, str) and not isinstance(value, str):
        raise EcahdError(f"parameter {spec.name} must be a string, got {value!r}")
    return value


def on_parameter_change(node: Node, specs: Sequence[ParamSpec], get_current: Callable[[], T],
                        apply: Callable[[T], None]) -> None:
    """Validate run-time changes of dynamic parameters with the node's dataclass and hand the
    new dataclass to ``apply``; a change that does not validate is rejected with its reason."""
    by_name = {spec.name: spec for spec in specs}

    def callback(changes) -> SetParametersResult:
        current = get_current()
        if current is None:
            return SetParametersResult(successful=False, reason="node is not configured")
        try:
            values = {}
            for change in changes:
                spec = by_name.get(change.name)
                if spec is None:
                    continue  # e.g. use_sim_time: rclpy's own
                values[change.name] = _checked(spec, change.value)
            new = replace(current, **values) if values else current
        except (EcahdError, TypeError) as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        if values:
            apply(new)
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(callback)


def read_parameters(node: Node, specs: Sequence[ParamSpec], cls: type[T]) -> T:
    """Read the declared parameters into ``cls`` (a frozen dataclass with one field per spec).
    Raises EcahdError naming the parameter when a value has the wrong type or is not finite;
    ``cls.__post_init__`` checks the ranges."""
    names = {f.name for f in fields(cls)}
    values = {}
    for spec in specs:
        if spec.name not in names:
            raise EcahdError(f"parameter {spec.name} has no field in {cls.__name__}")
        value = _checked(spec, node.get_parameter(spec.name).value)
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


# The parameters several nodes declare, defined once (name -> spec).
SHARED = {spec.name: spec for spec in [
    ParamSpec("map_name", DEFAULT_MAP, "name of the map on 'map' (checked against the "
                                          "checkpoint with the grid's fingerprint)"),
    ParamSpec("robot", "circle", "footprint preset: circle, quadruped, humanoid"),
    ParamSpec("footprint", "", "Nav2 footprint polygon '[[x, y], ...]' [m]; overrides robot"),
    ParamSpec("footprint_padding", 0.0, "[m] grows the footprint (Nav2 footprint_padding)"),
    ParamSpec("global_frame", "map", "frame of goals and plans (REP-105's map); odometry in "
                                     "another frame (odom) is placed in it through /tf"),
    ParamSpec("transform_tolerance", TRANSFORM_TOLERANCE, "[s] a transform of /tf at most this much older than "
                                          "the odometry it places is used (Nav2's "
                                          "transform_tolerance)"),
    ParamSpec("clearance_margin", 0.02, "[m] the exact checker judges local plans and "
                                        "waypoints with the footprint grown by this (ours: "
                                        "room for the controller's tracking error)"),
    ParamSpec("cost_margin", -1.0, "[m] J's cost map rises from 0 at this distance from an "
                                   "obstacle to 1 on its edge (DD's trigger and guidance, "
                                   "polishing, SD's collision-aware selection); -1 = by the "
                                   "map: 0.5 on maps over 50 000 cells (a building's speckle "
                                   "is then visible to J), else 0.1 (the paper's tables)"),
    ParamSpec("map_change_warn", 0.05, "an updated map of the same site (same cells, "
                                       "resolution and origin: a SLAM update) keeps the "
                                       "site's models; more than this share of its cells "
                                       "changed is warned about (the models learnt the old "
                                       "map: consider training again)"),
    ParamSpec("dd_model", "", "DD checkpoint path; '' = the shipped model for map_name; "
                              "'general' = the shipped segment-frame DD (any map) "
                              "(global_planner: compute_path_to_pose's dense path)"),
    ParamSpec("lanes", "", "a lane field of this map (`ecahd lanes`, learnt from the robot's "
                           "demonstrations): global_planner moves SD's waypoints and "
                           "local_refiner its local plans sideways onto where the robot was "
                           "driven in their direction (never into collision), and "
                           "global_planner plans round its keep-out places (never driven, "
                           "though the expert's routes cross them) as walls (a goal in one is "
                           "refused); '' = off; unreadable: the node fails at start-up; a map "
                           "it does not belong to: logged, planned without lanes"),
    ParamSpec("seed", 0, "seed of the sampler's torch.Generator (a seed reproduces the plans)"),
    ParamSpec("yaw_goal_tolerance", 0.25, "[rad] a goal with a heading (navigate_to_pose, or "
                                          "goal_pose with a non-zero orientation) is reached "
                                          "turned to within this (Nav2's goal checker); "
                                          "local_refiner turns in place at the goal"),
    ParamSpec("autostart", True, "configure and activate at start-up; false: wait, unconfigured, "
                                 "for a lifecycle manager (Nav2's lifecycle_manager)"),
    ParamSpec("scan_offset_x", 0.0, "[m] x of the LiDAR on base_link (the base_link -> "
                                    "base_scan transform; sim_bridge and local_refiner agree)"),
    ParamSpec("scan_offset_y", 0.0, "[m] y of the LiDAR on base_link"),
    ParamSpec("scan_offset_yaw", 0.0, "[rad] heading of the LiDAR on base_link"),
    ParamSpec("torch_threads", 1, "torch.set_num_threads (and interop threads) of this "
                                  "process: 1 keeps inference off the other cores"),
]}


def shared(*names: str) -> list[ParamSpec]:
    """The :data:`SHARED` specs of ``names``, in that order."""
    return [SHARED[name] for name in names]


def require_cost_margin(params) -> None:
    """``params.cost_margin`` must be > 0 m or -1 (by the map)."""
    require(params.cost_margin > 0 or params.cost_margin == -1, "cost_margin",
            params.cost_margin, "> 0 m, or -1 (by the map's size)")


def collision_cost(params, grid, footprint):
    """J of ``footprint`` on ``grid`` with the margin of ``params.cost_margin`` (-1: chosen by
    the map, :meth:`~ecahd_core.cost.CostConfig.for_map`): a CollisionCost."""
    from ecahd_core.cost import CollisionCost, CostConfig

    margin = None if params.cost_margin < 0 else params.cost_margin
    return CollisionCost.build(grid, footprint, CostConfig.for_map(grid, margin=margin))


def make_robot(params, *, margin: float = 0.0):
    """The Footprint of a params dataclass with robot, footprint and footprint_padding, grown
    by ``margin`` [m] more (the exact checker's clearance margin)."""
    from ecahd_core.footprint import make_footprint

    return make_footprint(robot_spec(params.robot, params.footprint),
                          padding=params.footprint_padding + margin)


def load_lanes(path: str):
    """The LaneField at ``path`` (``ecahd lanes``), or None for ''. An unreadable file raises
    EcahdError naming it: bad configuration fails the node at start-up."""
    if not path:
        return None
    from ecahd_core.lanes import LaneField

    return LaneField.load(path)


def lanes_for(field, grid, logger):
    """``field`` if it belongs to ``grid`` (its extent), else None with one error line (a map
    the lane field was not fitted on is planned on without lanes; the node keeps running)."""
    if field is None:
        return None
    from ecahd_core.errors import EcahdError

    try:
        field.check_map(grid)
    except EcahdError as exc:
        logger.error(f"lanes off on this map: {exc}")
        return None
    return field
