"""The manip_kin exceptions: one base class, two families, one subclass per kind of mistake.

* :class:`InputError` (also a ``ValueError``): the request cannot be valid as given — a bad
  argument, parameter, robot description or file. A CLI or a node exits with code 2.
* :class:`OperationError` (also a ``RuntimeError``): a valid request that could not be carried
  out — a node that died, a wait that timed out, a recording that could not be written.
  Exit code 1.

Every message says what was received and what would have been valid (or what failed), so a
CLI or a node can print it on one line as it is.

Each :class:`InputError` also carries a :class:`ProblemKind`, set where the problem is detected
(``InvalidArgumentError(text, kind=ProblemKind.LENGTH)``); a check that returns its reason rather
than raising returns a :class:`Problem`, the reason's text carrying the same kind. Nodes key their
throttled log lines on the kind, so one kind of bad message cannot hide another. A Problem is a
``str`` subclass, not a (kind, text) pair, because every caller already formats, slices, stores and
reports reasons as text (diagnostics, the CLI's "goal rejected: ...", returned lists of refusals):
they stay as they are, and only the few lines that key a log read ``.kind``.
"""

from __future__ import annotations

from collections.abc import Iterable
from enum import StrEnum


class ProblemKind(StrEnum):
    """What is wrong with a rejected input (a message, a goal, a trajectory): the key a node
    throttles its log lines by (``"goal:" + kind``), so the values are fixed words.

    Not the ``rejection_kind`` a generator reports (``invalid`` or ``unreachable``): that says
    whether a target could be valid at all, this says which check refused it.
    """

    FRAME = "frame"  # a header frame_id that is not the frame expected
    NON_FINITE = "finite"  # NaN or infinity
    REACH = "reach"  # a position farther from the base than the arm could ever be
    SPEED = "speed"  # a rate far beyond what the arm can do
    RANGE = "range"  # a joint position outside its range
    QUATERNION = "quaternion"  # an orientation that is not (close to) a unit quaternion
    LENGTH = "length"  # wrong counts: values, names missing or repeated
    OTHER = "other"  # anything else (undecodable bytes, an unknown name, ...)


class Problem(str):
    """The reason an input is refused (the one-line text every caller logs, stores and reports)
    with its :attr:`kind`.

    A ``str`` rather than a pair: callers keep formatting, slicing and comparing reasons as text
    (``f"rejected: {problem}"``, ``reason[:300]``, ``problem is None``) and read ``.kind`` only
    where they key a log line; plain ``str(problem)`` drops the kind (use :meth:`of`).

    Args:
        kind: which check refused the input.
        text: what was received and what is valid.
    """

    kind: ProblemKind

    def __new__(cls, kind: ProblemKind, text: str) -> Problem:
        problem = super().__new__(cls, text)
        problem.kind = ProblemKind(kind)
        return problem

    def __getnewargs__(self) -> tuple[ProblemKind, str]:  # copy and pickle build it with both
        return self.kind, str(self)

    def __repr__(self) -> str:
        return f"Problem({self.kind.name}, {super().__repr__()})"

    @classmethod
    def of(cls, reason: object) -> Problem:
        """``reason`` (an error, a :class:`Problem` or a plain text) as a :class:`Problem`: an
        error's or a problem's own kind, :attr:`ProblemKind.OTHER` for anything else."""
        kind = getattr(reason, "kind", None)
        return cls(kind if isinstance(kind, ProblemKind) else ProblemKind.OTHER, str(reason))


class ManipKinError(Exception):
    """Base class of every error manip_kin raises."""


class InputError(ManipKinError, ValueError):
    """A request that cannot be valid as given (exit code 2): argument, parameter, file.

    ``kind`` (keyword) says which check refused it; without one, the kind of a :class:`Problem`
    given as the message, else the class's own (:attr:`ProblemKind.OTHER` unless it says).
    """

    kind: ProblemKind = ProblemKind.OTHER

    def __init__(self, *args: object, kind: ProblemKind | None = None):
        super().__init__(*args)
        if kind is None and args and isinstance(args[0], Problem):
            kind = args[0].kind
        if kind is not None:
            self.kind = ProblemKind(kind)


class OperationError(ManipKinError, RuntimeError):
    """A valid request that could not be carried out (exit code 1)."""


#: Process exit codes: 2 for an :class:`InputError`, 1 for any other failure.
EXIT_INPUT_ERROR = 2
EXIT_FAILURE = 1
#: Stopped by Ctrl-C (128 + SIGINT, as a shell reports it).
EXIT_INTERRUPTED = 130


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

    kind = ProblemKind.NON_FINITE

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
