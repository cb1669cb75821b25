"""Declaring a node's parameters on rclpy from its config dataclass tree.

Defaults, descriptions, ranges and choices come from the tree (``core.parameters``); rclpy
checks the types and ranges of overrides (a params file or ``-p``) while declaring. Its
exceptions become ``ConfigError`` naming the parameter, and the tree then checks the choices
and combinations.
"""

from collections.abc import Callable
from typing import Any, TypeVar

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.parameters import parameter_table
from infinihand_ros.core.parameters import ParameterSpec
from rcl_interfaces.msg import FloatingPointRange
from rcl_interfaces.msg import IntegerRange
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node

ConfigT = TypeVar('ConfigT')


def descriptor_for(name: str, spec: ParameterSpec, default: Any) -> ParameterDescriptor:
    """Return the read-only descriptor of a parameter, with its range for numbers."""
    descriptor = ParameterDescriptor(name=name, description=spec.full_description,
                                     read_only=True)
    if spec.low is None or isinstance(default, bool):
        return descriptor
    if isinstance(default, int):
        descriptor.integer_range = [IntegerRange(from_value=int(spec.low),
                                                 to_value=int(spec.high), step=1)]
    else:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.low), to_value=float(spec.high), step=0.0)]
    return descriptor


def declare_parameters(node: Node, config_type: type[ConfigT],
                       build: Callable[[dict[str, Any]], ConfigT]) -> ConfigT:
    """Declare every parameter of ``config_type`` on ``node``; return the checked config.

    Args:
        node: the node to declare on.
        config_type: the node's config dataclass (owner of every parameter).
        build: builds the config from the flat values (``*_config_from_parameters``).

    Raises:
        ConfigError: naming the parameter for a wrong type, an out-of-range or a bad value.

    """
    values: dict[str, Any] = {}
    for name, (default, spec) in parameter_table(config_type).items():
        try:
            parameter = node.declare_parameter(name, default,
                                               descriptor_for(name, spec, default))
        except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
            raise ConfigError(f'parameter {name}: {exc}') from exc
        values[name] = parameter.value
    try:
        return build(values)
    except ConfigError as exc:
        raise ConfigError(f'parameter {exc}') from exc
