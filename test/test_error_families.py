"""Every exception manip_kin defines belongs to a ManipKinError family (InputError or OperationError).

A CLI or a node turns an error into its exit code by family (:func:`manip_kin.errors.exit_code_for`):
an exception class outside the families would end a process with a traceback or the wrong code.
"""

from __future__ import annotations

import importlib
import inspect
import pkgutil

import pytest

import manip_kin
from manip_kin.errors import InputError, ManipKinError, OperationError, exit_code_for
from manip_kin.ros.runtime.looping_node import LoopGaveUpError
from manip_kin.ros.wire.validation import InvalidMessageError


def _defined_exceptions() -> list[type]:
    found = []
    for info in pkgutil.walk_packages(manip_kin.__path__, "manip_kin."):
        try:
            module = importlib.import_module(info.name)
        except ModuleNotFoundError as error:
            if (error.name or "").startswith("manip_kin"):
                raise
            continue  # an optional third-party dependency this machine lacks
        for _, value in inspect.getmembers(module, inspect.isclass):
            if issubclass(value, BaseException) and value.__module__ == info.name:
                found.append(value)
    return found


def test_every_exception_defined_in_the_package_is_in_a_family():
    exceptions = _defined_exceptions()
    assert InvalidMessageError in exceptions and LoopGaveUpError in exceptions
    outside = [f"{e.__module__}.{e.__qualname__}" for e in exceptions if not issubclass(e, ManipKinError)]
    assert not outside
    unfamilied = [
        f"{e.__module__}.{e.__qualname__}"
        for e in exceptions
        if e is not ManipKinError and not issubclass(e, (InputError, OperationError))
    ]
    assert not unfamilied


@pytest.mark.parametrize(
    ("error", "family", "code"),
    [
        (InvalidMessageError("joint state positions contain NaN"), InputError, 2),
        (LoopGaveUpError("every cycle failed for 3 s"), OperationError, 1),
    ],
)
def test_message_and_loop_errors_carry_their_family_and_exit_code(error, family, code):
    assert isinstance(error, family) and exit_code_for(error) == code
    # The except sites that caught them before still do.
    assert isinstance(error, ValueError if family is InputError else RuntimeError)
