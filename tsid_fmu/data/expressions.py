"""Derived channels: a small, safe expression language over data columns.

A study computes channels the FMU needs from the logged ones, e.g. the output force of
two compression-only load cells, ``F_o = "F_of - F_or"``, or the stage velocity and
acceleration of a position-controlled stage that logs its position only,
``v_o = "der(x_o)"`` and ``a_o = "der(x_o, 2)"``.

Study and data files travel between colleagues and vendors, so an expression is never
handed to ``eval``: it is parsed with :mod:`ast` and only these nodes are evaluated:

* number literals (``2``, ``0.5``, ``1e308``; not booleans, strings or complex);
* names of data columns (and the constants ``pi`` and ``e``);
* ``+ - * / **``, unary ``-`` and ``+``, and comparisons (giving 1.0 or 0.0);
* calls of the functions in :data:`FUNCTIONS` by name, with positional arguments.

Attribute access, subscripts, keywords, lambdas, comprehensions and every other call are
refused with a :class:`~tsid_fmu.errors.DataError` that names the channel and the part
of the expression at fault, before anything is evaluated.
"""

from __future__ import annotations

import ast
import math
from collections.abc import Callable, Mapping

import numpy as np

from tsid_fmu.data.derivative import DEFAULT_WINDOW, derivative
from tsid_fmu.data.names import describe_columns
from tsid_fmu.errors import DataError

__all__ = ["CONSTANTS", "FUNCTIONS", "MAX_LENGTH", "evaluate", "names_used"]

MAX_LENGTH = 2000
"""Longest expression accepted, in characters."""

MAX_DEPTH = 64
"""Deepest nesting of operations accepted."""

CONSTANTS = {"pi": math.pi, "e": math.e}

_LARGEST = int(np.finfo(np.float64).max)
"""Largest integer literal that converts to a float (larger ones overflow)."""

_UNARY: dict[str, Callable[..., np.ndarray]] = {
    name: getattr(np, name)
    for name in (
        "abs sqrt exp expm1 log log1p log10 sin cos tan arcsin arccos arctan sinh cosh "
        "tanh arcsinh arccosh arctanh sign"
    ).split()
}
_BINARY: dict[str, Callable[..., np.ndarray]] = {
    "arctan2": np.arctan2,
    "minimum": np.minimum,
    "maximum": np.maximum,
}

FUNCTIONS = sorted([*_UNARY, *_BINARY, "where", "der"])
"""Functions an expression may call: numpy's elementwise ones, ``where(c, a, b)``, and
``der(column, order=1, window=21)`` (Savitzky-Golay derivative, see
:func:`tsid_fmu.data.derivative.derivative`)."""

_OPS: dict[type, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    ast.Add: np.add,
    ast.Sub: np.subtract,
    ast.Mult: np.multiply,
    ast.Div: np.divide,
    ast.Pow: np.power,
}
_COMPARE: dict[type, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    ast.Lt: np.less,
    ast.LtE: np.less_equal,
    ast.Gt: np.greater,
    ast.GtE: np.greater_equal,
    ast.Eq: np.equal,
    ast.NotEq: np.not_equal,
}


class _Refused(Exception):
    """An expression uses something the language does not allow (message for users)."""


def _parse(expression: str) -> ast.Expression:
    if not isinstance(expression, str):
        raise _Refused(f"must be a string, got {type(expression).__name__}")
    if len(expression) > MAX_LENGTH:
        raise _Refused(f"is longer than {MAX_LENGTH} characters")
    try:
        tree = ast.parse(expression.strip(), mode="eval")
    except (SyntaxError, ValueError, RecursionError, MemoryError) as exc:
        raise _Refused(f"is not a valid expression ({type(exc).__name__})") from None
    _check(tree.body, depth=0)
    return tree


def _describe(node: ast.AST) -> str:
    return type(node).__name__.lower()


def _check(node: ast.AST, depth: int) -> None:
    """Refuse every node outside the language, walking the tree without evaluating."""
    if depth > MAX_DEPTH:
        raise _Refused(f"nests operations more than {MAX_DEPTH} deep")
    if isinstance(node, ast.Constant):
        if isinstance(node.value, bool) or not isinstance(node.value, int | float):
            raise _Refused(f"uses the literal {node.value!r}; only numbers are allowed")
        if isinstance(node.value, int) and abs(node.value) > _LARGEST:
            digits = len(str(abs(node.value)))  # parsed, so within the str() limit
            raise _Refused(f"uses an integer of {digits} digits, more than a float holds")
        return
    if isinstance(node, ast.Name):
        return
    children: list[ast.AST]
    if isinstance(node, ast.BinOp) and type(node.op) in _OPS:
        children = [node.left, node.right]
    elif isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub | ast.UAdd):
        children = [node.operand]
    elif isinstance(node, ast.Compare) and all(type(op) in _COMPARE for op in node.ops):
        children = [node.left, *node.comparators]
    elif isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            what = node.func.id if isinstance(node.func, ast.Name) else _describe(node.func)
            raise _Refused(f"calls {what!r}; allowed functions: {', '.join(FUNCTIONS)}")
        if node.keywords:
            raise _Refused(f"passes keyword arguments to {node.func.id}(); use positions")
        children = list(node.args)
    else:
        raise _Refused(f"uses a {_describe(node)} expression, which is not allowed")
    for child in children:
        _check(child, depth + 1)


def names_used(expression: str) -> set[str]:
    """Return the column names an expression refers to (after checking it is allowed).

    Raises
    ------
    DataError
        The expression is not allowed (the message says why, not where it came from).
    """
    try:
        tree = _parse(expression)
    except _Refused as exc:
        raise DataError(f"expression {exc}") from None
    return {
        n.id
        for n in ast.walk(tree)
        if isinstance(n, ast.Name) and n.id not in CONSTANTS and n.id not in FUNCTIONS
    }


class _Evaluator:
    """Evaluate a checked tree over columns of equal length."""

    def __init__(self, columns: Mapping[str, np.ndarray], sample_time: float) -> None:
        self.columns = columns
        self.sample_time = sample_time
        self.n = len(next(iter(columns.values()))) if columns else 0

    def __call__(self, node: ast.AST) -> np.ndarray:
        if isinstance(node, ast.Constant):
            return np.full(self.n, float(node.value))
        if isinstance(node, ast.Name):
            if node.id in self.columns:
                return np.asarray(self.columns[node.id], dtype=np.float64)
            if node.id in CONSTANTS:
                return np.full(self.n, CONSTANTS[node.id])
            raise _Refused(f"uses unknown name {node.id!r}")
        if isinstance(node, ast.BinOp):
            return _OPS[type(node.op)](self(node.left), self(node.right))
        if isinstance(node, ast.UnaryOp):
            value = self(node.operand)
            return -value if isinstance(node.op, ast.USub) else value
        if isinstance(node, ast.Compare):
            return self._compare(node)
        return self._call(node)  # type: ignore[arg-type]

    def _compare(self, node: ast.Compare) -> np.ndarray:
        left = self(node.left)
        result = np.ones(self.n, dtype=bool)
        for op, right_node in zip(node.ops, node.comparators, strict=True):
            right = self(right_node)
            result &= _COMPARE[type(op)](left, right)
            left = right
        return result.astype(np.float64)

    def _call(self, node: ast.Call) -> np.ndarray:
        name = node.func.id  # type: ignore[attr-defined]
        args = node.args
        arity = {"where": (3, 3), "der": (1, 3)}.get(name, (2, 2) if name in _BINARY else (1, 1))
        if not arity[0] <= len(args) <= arity[1]:
            raise _Refused(f"calls {name}() with {len(args)} argument(s); it takes {arity}")
        if name == "der":
            return self._der(args)
        values = [self(a) for a in args]
        if name == "where":
            return np.where(values[0] != 0, values[1], values[2])
        return (_BINARY.get(name) or _UNARY[name])(*values)

    def _der(self, args: list[ast.expr]) -> np.ndarray:
        order = _integer(args[1], "der() order") if len(args) > 1 else 1
        window = _integer(args[2], "der() window") if len(args) > 2 else DEFAULT_WINDOW
        signal = self(args[0])
        try:
            return derivative(signal, self.sample_time, order=order, window=window)
        except DataError as exc:
            raise _Refused(str(exc)) from None


def _integer(node: ast.expr, what: str) -> int:
    if not isinstance(node, ast.Constant) or isinstance(node.value, bool):
        raise _Refused(f"gives {what} as an expression; it must be a whole number")
    if not isinstance(node.value, int):
        raise _Refused(f"gives {what} {node.value!r}; it must be a whole number")
    return node.value


def evaluate(
    expression: str,
    columns: Mapping[str, np.ndarray],
    *,
    sample_time: float,
    channel: str = "expression",
    source: str = "data",
) -> np.ndarray:
    """Evaluate a derived-channel expression over data columns.

    Parameters
    ----------
    expression : str
        The expression, e.g. ``"F_of - F_or"`` or ``"der(x_o, 2)"``.
    columns : mapping of str to numpy.ndarray
        Data columns of equal length by name.
    sample_time : float
        Sampling interval in seconds (for ``der``).
    channel : str
        Name of the derived channel, for messages.
    source : str
        The data file (or ``"<frame>"``), for messages.

    Returns
    -------
    numpy.ndarray
        ``float64`` values, one per sample.

    Raises
    ------
    DataError
        The expression uses anything outside the language, an unknown name, or calls a
        function wrongly. The message names the file and the channel, never the data.

    Examples
    --------
    >>> import numpy as np
    >>> evaluate("a - 2 * b", {"a": np.array([3.0]), "b": np.array([1.0])}, sample_time=1.0)
    array([1.])
    """
    try:
        tree = _parse(expression)
        with np.errstate(all="ignore"):
            value = _Evaluator(columns, sample_time)(tree.body)
    except _Refused as exc:
        long = isinstance(expression, str) and len(expression) > 80
        shown = expression[:60] + "..." if long else expression
        raise DataError(
            f"{source}: derived channel {channel!r} = {shown!r} {exc}; "
            f"{describe_columns(list(columns))} (functions: {', '.join(FUNCTIONS)})"
        ) from None
    n = len(next(iter(columns.values()))) if columns else 0
    return np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy()
