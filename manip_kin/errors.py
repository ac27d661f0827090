"""The manip_kin exceptions: one base class, one subclass per kind of mistake.

Every message says what was received and what would have been valid, so a
CLI or a node can print it on one line as it is.
"""

from __future__ import annotations

from collections.abc import Iterable


class ManipKinError(ValueError):
    """Base class of every error manip_kin raises for bad input."""


class UnknownRobotError(ManipKinError):
    """A robot name that is neither bundled nor an existing file."""

    def __init__(self, name: str, available: Iterable[str]):
        self.name = name
        self.available = tuple(available)
        super().__init__(
            f"unknown robot {name!r}: not a bundled robot ({', '.join(self.available)}) "
            "nor an existing .yaml/.urdf file"
        )


class UnknownFrameError(ManipKinError):
    """A frame name or index the model does not have."""

    def __init__(self, frame: object, valid: Iterable[str]):
        self.frame = frame
        self.valid = tuple(valid)
        super().__init__(f"unknown frame {frame!r}; valid frames: {', '.join(self.valid)}")


class JointCountError(ManipKinError):
    """A joint vector whose length does not match the model."""

    def __init__(self, what: str, received: int, expected: int):
        self.received = received
        self.expected = expected
        super().__init__(f"{what} has {received} values, the robot has {expected} joints")


class NotARotationError(ManipKinError):
    """A 3x3 matrix that is not a proper rotation (orthonormal, det +1)."""


class NonFiniteError(ManipKinError):
    """An input holding NaN or infinity."""

    def __init__(self, what: str):
        super().__init__(f"{what} contains NaN or infinity; only finite values are valid")


class ModelFileError(ManipKinError):
    """A robot description (YAML or URDF) that cannot be used, with file and field."""

    def __init__(self, source: str, field: str, problem: str):
        self.source = source
        self.field = field
        self.problem = problem
        super().__init__(f"{source}: field '{field}': {problem}")


class InvalidArgumentError(ManipKinError):
    """A parameter outside its valid range (a negative gain, a zero time step, ...)."""


def check_finite(values, what: str):
    """Raise :class:`NonFiniteError` unless every value is finite; return the array."""
    import numpy as np

    array = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(array)):
        raise NonFiniteError(what)
    return array
