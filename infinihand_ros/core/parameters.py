"""Node parameters owned by one dataclass tree: defaults, descriptions, ranges and choices.

Each field of a node's config dataclass is declared with ``parameter`` (or ``nested`` for a
sub-tree); its dotted path is the ROS parameter name (field ``beta`` of ``smoothing``:
``smoothing.beta``). From the tree alone come the node's declarations (``parameter_table``:
default, description, numeric range, choices), the check of string choices
(``check_parameters``, from ``__post_init__``) and the shipped params file (``params_file_text``;
a test compares it with the file in ``config/``).
"""

from collections.abc import Callable
import dataclasses
from dataclasses import dataclass
import textwrap
from typing import Any, Final

from infinihand_ros.core.errors import ConfigError

ROS_PARAMETERS_KEY: Final = 'ros__parameters'
#: The params-file key that matches every node name (ROS 2 wildcard).
ANY_NODE_KEY: Final = '/**'
_SPEC: Final = 'parameter'
#: Width of the generated params files.
LINE_WIDTH: Final = 99


@dataclass(frozen=True)
class ParameterSpec:
    """What a parameter means and which values it takes.

    Attributes:
        description: one sentence shown by parameter tools (choices are appended).
        low: smallest value of a numeric parameter (None: no range).
        high: largest value of a numeric parameter.
        choices: the values a string parameter may take (empty: any).

    """

    description: str
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()

    @property
    def full_description(self) -> str:
        """Return the description with the choices, as parameter tools show it."""
        if not self.choices:
            return self.description
        return f"{self.description} One of: {', '.join(self.choices)}."


def parameter(default: Any, description: str, low: float | None = None,
              high: float | None = None, choices: tuple[str, ...] = ()) -> Any:
    """Return a dataclass field that is a node parameter with this default and spec."""
    spec = ParameterSpec(description, low, high, choices)
    return dataclasses.field(default=default, metadata={_SPEC: spec})


def nested(factory: Callable[[], Any]) -> Any:
    """Return a dataclass field holding a sub-tree of parameters (a dataclass)."""
    return dataclasses.field(default_factory=factory)


def check_parameters(config: Any, prefix: str = '') -> None:
    """Raise ConfigError naming the parameter for a value outside its choices or its range.

    Call it from ``__post_init__``: the checks come from the fields' specs, so a range or a
    choice is written once.
    """
    for field in dataclasses.fields(config):
        spec = field.metadata.get(_SPEC)
        if spec is None:
            continue
        value = getattr(config, field.name)
        name = f'{prefix}{field.name}'
        if spec.choices and value not in spec.choices:
            raise ConfigError(f'{name}: must be one of {list(spec.choices)}, got {value!r}')
        numeric = isinstance(value, (int, float)) and not isinstance(value, bool)
        if numeric and spec.low is not None and not spec.low <= value <= spec.high:
            raise ConfigError(f'{name}: must be in [{spec.low}, {spec.high}], got {value!r}')


def parameter_table(config_type: type, prefix: str = '') -> dict[str, tuple[Any, ParameterSpec]]:
    """Return every parameter of the tree as dotted name -> (default, spec), in field order.

    Defaults are those of ``config_type()``: a sub-tree's defaults are its field's default
    factory's (which may differ from the sub-tree class's own).

    Raises:
        TypeError: for a field that is neither a parameter nor a nested dataclass (a tree
            that does not say what one of its settings means).

    """
    return _table(config_type(), prefix)


def _table(defaults: Any, prefix: str) -> dict[str, tuple[Any, ParameterSpec]]:
    """Return the parameters of a default tree instance (see ``parameter_table``)."""
    table: dict[str, tuple[Any, ParameterSpec]] = {}
    for field in dataclasses.fields(defaults):
        name = f'{prefix}{field.name}'
        value = getattr(defaults, field.name)
        if dataclasses.is_dataclass(value):
            table.update(_table(value, f'{name}.'))
        elif _SPEC in field.metadata:
            table[name] = (value, field.metadata[_SPEC])
        else:
            raise TypeError(f'{type(defaults).__name__}.{field.name} has no parameter spec')
    return table


def parameters_help(config_type: type) -> str:
    """Return one line per parameter: ``name (default): description`` (for ``--help``)."""
    return '\n'.join(f'  {name} ({default!r}): {spec.full_description}'
                     for name, (default, spec) in parameter_table(config_type).items())


def unflatten(values: dict[str, Any]) -> dict[str, Any]:
    """Return dotted names as nested mappings (``{'a.b': 1}`` -> ``{'a': {'b': 1}}``)."""
    tree: dict[str, Any] = {}
    for name, value in values.items():
        *parents, leaf = name.split('.')
        node = tree
        for parent in parents:
            node = node.setdefault(parent, {})
        node[leaf] = value
    return tree


def params_file_text(config_type: type, header: str) -> str:
    """Return the ROS 2 params file of a tree's defaults (keyed ``/**``), described in comments.

    Args:
        config_type: the node's config dataclass.
        header: comment lines (without ``#``) put at the top of the file.

    """
    lines = [f'# {line}'.rstrip() for line in header.strip('\n').split('\n')]
    lines += [f'{ANY_NODE_KEY}:', f'  {ROS_PARAMETERS_KEY}:']
    opened: list[str] = []
    for name, (default, spec) in parameter_table(config_type).items():
        *parents, leaf = name.split('.')
        common = 0
        while common < min(len(opened), len(parents)) and opened[common] == parents[common]:
            common += 1
        for depth in range(common, len(parents)):
            lines.append(f"{'  ' * (depth + 2)}{parents[depth]}:")
        opened = parents
        indent = '  ' * (len(parents) + 2)
        lines += [f'{indent}# {line}' for line in
                  textwrap.wrap(spec.full_description, LINE_WIDTH - len(indent) - 2)]
        lines.append(f'{indent}{leaf}: {_yaml_scalar(default)}')
    return '\n'.join(lines) + '\n'


def _yaml_scalar(value: Any) -> str:
    """Return a default as a YAML scalar of the same type (floats keep a decimal point)."""
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, str):
        return "''" if not value else value
    return repr(value)
