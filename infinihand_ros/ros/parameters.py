"""Declaring a node's parameters on rclpy, with descriptions, types and ranges.

``declare_parameters`` serves both nodes: defaults from their YAML file
(``config/estimator.yaml``, ``config/bundle_adjustment.yaml``), descriptions and ranges from
their ``ParameterSpec`` tables. rclpy checks the types and ranges of overrides (a
params file or ``-p``) while declaring; its exceptions are turned into ``ConfigError`` naming
the parameter, and the config tree then checks the choices.
"""

from typing import Any

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.ros.estimator.config import estimator_config_from_parameters
from infinihand_ros.ros.estimator.config import EstimatorConfig
from infinihand_ros.ros.estimator.config import load_estimator_defaults
from infinihand_ros.ros.estimator.parameter_specs import PARAMETER_SPECS
from infinihand_ros.ros.estimator.parameter_specs import ParameterSpec
from rcl_interfaces.msg import FloatingPointRange
from rcl_interfaces.msg import IntegerRange
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.exceptions import InvalidParameterValueException
from rclpy.node import Node


def descriptor_for(name: str, spec: ParameterSpec, default: Any) -> ParameterDescriptor:
    """Return the read-only descriptor of a parameter, with its range for numbers."""
    descriptor = ParameterDescriptor(name=name, description=spec.description, read_only=True)
    if spec.low is None or isinstance(default, bool):
        return descriptor
    if isinstance(default, int):
        descriptor.integer_range = [IntegerRange(from_value=int(spec.low),
                                                 to_value=int(spec.high), step=1)]
    else:
        descriptor.floating_point_range = [FloatingPointRange(
            from_value=float(spec.low), to_value=float(spec.high), step=0.0)]
    return descriptor


def declare_parameters(node: Node, defaults: dict[str, Any],
                       specs: dict[str, ParameterSpec], source: str) -> dict[str, Any]:
    """Declare every parameter of ``defaults`` on ``node``; return the values it got.

    Args:
        node: the node to declare on.
        defaults: flat (dotted) parameter names and their default values.
        specs: description and range of every parameter (the same names).
        source: the defaults file, named when it does not match the specs.

    Raises:
        ConfigError: naming the parameter for a wrong type or an out-of-range value, or when
            the defaults and the specs name different parameters.

    """
    if set(defaults) != set(specs):
        raise ConfigError(f'{source} and the parameter specs differ: '
                          f'{sorted(set(defaults) ^ set(specs))}')
    values: dict[str, Any] = {}
    for name, default in defaults.items():
        try:
            parameter = node.declare_parameter(name, default,
                                               descriptor_for(name, specs[name], default))
        except (InvalidParameterTypeException, InvalidParameterValueException) as exc:
            raise ConfigError(f'parameter {name}: {exc}') from exc
        values[name] = parameter.value
    return values


def declare_estimator_parameters(node: Node) -> EstimatorConfig:
    """Declare every parameter on ``node`` and return the checked config.

    Raises:
        ConfigError: naming the parameter for a wrong type, an out-of-range or bad value, or a
            defaults file that does not match the specs.

    """
    values = declare_parameters(node, load_estimator_defaults(), PARAMETER_SPECS,
                                'config/estimator.yaml')
    try:
        return estimator_config_from_parameters(values)
    except ConfigError as exc:
        raise ConfigError(f'parameter {exc}') from exc
