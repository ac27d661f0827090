"""The manip_kin exceptions: one base class, two families, one subclass per kind of mistake.

* :class:`InputError` (also a ``ValueError``): the request cannot be valid as given — a bad
  argument, parameter, robot description or file. A CLI or a node exits with code 2.
* :class:`OperationError` (also a ``RuntimeError``): a valid request that could not be carried
  out — a node that died, a wait that timed out, a recording that could not be written.
  Exit code 1.

Every message says what was received and what would have been valid (or what failed), so a
CLI or a node can print it on one line as it is.
"""

from __future__ import annotations

from collections.abc import Iterable


class ManipKinError(Exception):
    """Base class of every error manip_kin raises."""


class InputError(ManipKinError, ValueError):
    """A request that cannot be valid as given (exit code 2): argument, parameter, file."""


class OperationError(ManipKinError, RuntimeError):
    """A valid request that could not be carried out (exit code 1)."""


#: Process exit codes: 2 for an :class:`InputError`, 1 for any other failure.
EXIT_INPUT_ERROR = 2
EXIT_FAILURE = 1


def exit_code_for(error: BaseException) -> int:
    """The process exit code for an error: 2 for bad input, 1 for a failure."""
    return EXIT_INPUT_ERROR if isinstance(error, InputError) else EXIT_FAILURE


#: Characters of a received value an error message quotes at most.
QUOTE_LIMIT = 80


def bounded_repr(value: object, limit: int = QUOTE_LIMIT) -> str:
    """``repr(value)`` cut to about ``limit`` characters (``...`` and the full length when cut).

    Refusals quote what they received; a 100k-element array or a huge string must not
    become a 500 kB log line.
    """
    if isinstance(value, (list, tuple, dict, set)) and len(value) > limit:
        text = f"{type(value).__name__} of {len(value)} items"
        return text
    text = repr(value)
    if len(text) <= limit:
        return text
    return f"{text[: limit - 3]}... ({len(text)} characters)"


class UnknownRobotError(InputError):
    """A robot name that is neither bundled nor an existing file."""

    def __init__(self, name: str, available: Iterable[str]):
        self.name = name
        self.available = tuple(available)
        super().__init__(
            f"unknown robot {name!r}: not a bundled robot ({', '.join(self.available)}) "
            "nor an existing robot file (a robot YAML or a URDF, told apart by content)"
        )


class UnknownFrameError(InputError):
    """A frame name or index the model does not have."""

    def __init__(self, frame: object, valid: Iterable[str]):
        self.frame = frame
        self.valid = tuple(valid)
        super().__init__(f"unknown frame {frame!r}; valid frames: {', '.join(self.valid)}")


class JointCountError(InputError):
    """A joint vector whose length does not match the model."""

    def __init__(self, what: str, received: int, expected: int):
        self.received = received
        self.expected = expected
        super().__init__(f"{what} has {received} values, the robot has {expected} joints")


class NotARotationError(InputError):
    """A 3x3 matrix that is not a proper rotation (orthonormal, det +1)."""


class NonFiniteError(InputError):
    """An input holding NaN or infinity."""

    def __init__(self, what: str):
        super().__init__(f"{what} contains NaN or infinity; only finite values are valid")


class ModelFileError(InputError):
    """A robot description (YAML or URDF) that cannot be used, with file and field."""

    def __init__(self, source: str, field: str, problem: str):
        self.source = source
        self.field = field
        self.problem = problem
        super().__init__(f"{source}: field '{field}': {problem}")


class InvalidArgumentError(InputError):
    """A parameter outside its valid range (a negative gain, a zero time step, ...)."""


def check_finite(values, what: str):
    """Raise :class:`NonFiniteError` unless every value is finite; return the array."""
    import numpy as np

    array = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(array)):
        raise NonFiniteError(what)
    return array
