"""Inline a plain-float Python function into generated straight-line code.

The generated control step and IK iteration (:mod:`manip_kin.codegen.control_step`) run on local
variables: a call costs more than the arithmetic of a small function. Rather than keep a
second, hand-written copy of such a function as a source template, the generator takes the
function's own source and inlines it: arguments become the caller's expressions, locals get
fresh names (:class:`manip_kin.codegen.ir.Names`), and the final ``return`` becomes an assignment to the caller's names. So the
function stays the one definition, tested as Python, and the generated code follows it.

Only simple functions qualify: positional arguments, one ``return`` as the last statement,
no nested functions, closures or ``global``; names the function reads but does not assign
(``sqrt``, ``max``) must exist in the generated code's namespace.
"""

from __future__ import annotations

import ast
import inspect
import textwrap
from collections.abc import Callable, Sequence

from manip_kin.codegen.ir import Names


class _Renamer(ast.NodeTransformer):
    def __init__(self, mapping: dict[str, str], constants: dict[str, int | float]):
        self.mapping = mapping
        self.constants = constants

    def visit_Name(self, node: ast.Name) -> ast.expr:
        if node.id in self.constants and isinstance(node.ctx, ast.Load):
            return ast.copy_location(ast.Constant(value=self.constants[node.id]), node)
        return ast.copy_location(ast.Name(id=self.mapping.get(node.id, node.id), ctx=node.ctx), node)


def _number(text: str) -> int | float | None:
    """The value of a non-negative int or float literal (``3``, ``1e-4``), else None (a
    negative one stays an expression: a constant -1 as the base of ``**`` would need brackets)."""
    try:
        value = ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return None
    return value if type(value) in (int, float) and value >= 0 else None


def inline_lines(
    function: Callable, arguments: Sequence[str], results: Sequence[str], names: Names, prefix: str
) -> list[str]:
    """Statements computing ``results = function(*arguments)`` in place.

    Args:
        function: the function to inline (see the module docstring for what qualifies).
        arguments: one expression per parameter; a plain name or a number literal is
            substituted, anything else is first assigned to a prefixed local.
        results: names the returned value is unpacked into (one name for a non-tuple return).
        names: the generated function's names: each local of ``function`` becomes a fresh one.
        prefix: prefix of those locals (readability only: they are fresh whatever it is).

    Raises:
        ValueError: the function does not qualify.
    """
    tree = ast.parse(textwrap.dedent(inspect.getsource(function)))
    definition = tree.body[0]
    if not isinstance(definition, ast.FunctionDef):
        raise ValueError(f"{function.__name__} is not a plain function")
    parameters = [a.arg for a in definition.args.args]
    if definition.args.vararg or definition.args.kwarg or definition.args.kwonlyargs or definition.args.defaults:
        raise ValueError(f"{function.__name__}: only positional parameters without defaults can be inlined")
    if len(arguments) != len(parameters):
        raise ValueError(f"{function.__name__} takes {len(parameters)} arguments, got {len(arguments)}")
    body = list(definition.body)
    if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant):
        body = body[1:]  # the docstring
    if not body or not isinstance(body[-1], ast.Return) or body[-1].value is None:
        raise ValueError(f"{function.__name__}: the last statement must return a value")
    for node in ast.walk(ast.Module(body=body[:-1], type_ignores=[])):
        if isinstance(node, (ast.Return, ast.FunctionDef, ast.Lambda, ast.Global, ast.Nonlocal, ast.Yield)):
            raise ValueError(f"{function.__name__}: {type(node).__name__} cannot be inlined")
    assigned = {
        node.id
        for node in ast.walk(ast.Module(body=body, type_ignores=[]))
        if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store)
    }
    mapping = {name: names.fresh(prefix + name) for name in sorted(assigned)}
    constants: dict[str, int | float] = {}
    lines = []
    for parameter, argument in zip(parameters, arguments):
        if argument.isidentifier():
            mapping[parameter] = argument
        elif _number(argument) is not None and parameter not in assigned:
            # A literal goes in as itself, so that the compiler folds arithmetic on it.
            constants[parameter] = _number(argument)
        else:
            mapping.setdefault(parameter, names.fresh(prefix + parameter))
            lines.append(f"{mapping[parameter]} = {argument}")
    renamer = _Renamer(mapping, constants)
    statements = [renamer.visit(statement) for statement in body[:-1]]
    returned = renamer.visit(body[-1]).value
    lines += [ast.unparse(statement) for statement in statements]
    read = {node.id for node in ast.walk(returned) if isinstance(node, ast.Name)}
    if isinstance(returned, ast.Tuple) and len(returned.elts) == len(results) and not read & set(results):
        # One assignment per value: no tuple is built and unpacked.
        lines += [f"{name} = {ast.unparse(value)}" for name, value in zip(results, returned.elts)]
    else:
        target = ", ".join(results) + ("," if len(results) == 1 and isinstance(returned, ast.Tuple) else "")
        lines.append(f"{target} = {ast.unparse(returned)}")
    return [line for text in lines for line in text.split("\n")]
