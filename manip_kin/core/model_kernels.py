"""What is built from one robot model on first use, kept beside the model and dying with it.

A :class:`~manip_kin.core.model.RobotModel` is immutable; what is derived from it and costly to
build (its unrolled kinematics per frame, IK problems, closed-form solvers, default tasks)
lives in the model's :class:`ModelKernels`, one per model. The generated code itself is
shared between models of the same structure through :mod:`manip_kin.codegen.kernel_cache`; this
holds the functions bound for this model. Keys are small tuples (a frame index, task rows),
so each model's set is bounded by its frames and tasks; nothing is keyed on ``id()``, and a
dropped model frees all of it.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable
from typing import TypeVar

T = TypeVar("T")


class ModelKernels:
    """Values derived from one model, each built once on first request (thread-safe)."""

    def __init__(self):
        self._built: dict[Hashable, object] = {}
        self._lock = threading.RLock()

    def __len__(self) -> int:
        return len(self._built)

    def __reduce__(self):
        # A copied or pickled model rebuilds what it needs (a lock does not copy).
        return (ModelKernels, ())

    def get(self, key: Hashable, build: Callable[..., T], *arguments) -> T:
        """The value for ``key``, built as ``build(*arguments)`` the first time."""
        try:
            return self._built[key]  # type: ignore[return-value]
        except KeyError:
            pass
        with self._lock:  # two threads asking at once build it once
            if key not in self._built:
                self._built[key] = build(*arguments)
            return self._built[key]  # type: ignore[return-value]
