"""The project's exception family: each error names the input, the value and the fix."""


class InfiniHandError(Exception):
    """Base class of every error raised on purpose by infinihand_ros."""


class InputError(InfiniHandError, ValueError):
    """A frame, array, message or argument that cannot be used as given."""


class ConfigError(InfiniHandError, ValueError):
    """A configuration file or value that is unknown, mistyped or out of range."""


class CheckpointError(InfiniHandError):
    """A model checkpoint or model file that is missing, unreadable or does not match."""


class BagError(InfiniHandError):
    """A rosbag that is missing, corrupt or lacks a required topic."""


class ModelOutputError(InfiniHandError):
    """The network gave non-finite outputs: its weights are at fault, not the input."""


class EngineStateError(InfiniHandError, RuntimeError):
    """The engine was used out of its contract (after ``close()``, from two threads at once)."""
