"""Convert pymoca expression trees into CasADi ``SX`` expressions.

Two conversions of the same equations are made:

``live``
    Relations (``<``, ``<=``, ``>``, ``>=``) are evaluated wherever the expression is
    evaluated. Co-Simulation uses this form: its integrator locates the sign changes of
    the relations inside a step.
``frozen``
    Every relation outside ``noEvent(...)`` is replaced by a symbol ``c_k`` (value 0 or
    1): a discrete state that Model Exchange changes only at events. The right-hand side
    is then smooth between events, whatever branches the ``if``-expressions have, and the
    relation itself becomes the event indicator ``z_k = hi - lo`` of :class:`Relation`.

``abs`` and ``sign`` are continuous-time functions here, as the Modelica specification
defines them (``noEvent(if v >= 0 then v else -v)``): they generate no events.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from tsid_fmu.errors import BuildError

__all__ = ["Converter", "Relation", "expr_text"]

_UNARY = {
    "abs": "fabs",
    "sign": "sign",
    "sqrt": "sqrt",
    "sin": "sin",
    "cos": "cos",
    "tan": "tan",
    "asin": "arcsin",
    "acos": "arccos",
    "atan": "arctan",
    "sinh": "sinh",
    "cosh": "cosh",
    "tanh": "tanh",
    "exp": "exp",
    "log": "log",
    "log10": "log10",
    "floor": "floor",
    "ceil": "ceil",
}

# Relations as (lo, hi, strict): a < b -> (a, b, True), a >= b -> (b, a, False), ...
_RELATIONS = {"<": (0, True), "<=": (0, False), ">": (1, True), ">=": (1, False)}


@dataclass
class Relation:
    """A relation of the model that generates state events (Model Exchange).

    Attributes
    ----------
    sym : casadi.SX
        Symbol standing for the value of the relation (0 or 1) in the frozen equations.
    lo, hi : casadi.SX
        Operands of ``lo < hi`` (``strict``) or ``lo <= hi``, in the frozen form (they may
        contain the symbols of other relations).
    strict : bool
        ``True`` for ``<``, ``False`` for ``<=``.
    text : str
        The relation as written in the model, for documentation and messages.
    """

    sym: Any
    lo: Any
    hi: Any
    strict: bool
    text: str


class Converter:
    """Convert pymoca expression trees into CasADi SX expressions.

    Parameters
    ----------
    ca, ast : module
        ``casadi`` and ``pymoca.ast``.
    symbols : dict
        Name -> SX symbol (or constant) of every variable that may appear.
    where : str
        Prefix of error messages (file, model, equation).
    relations : list of Relation, optional
        If given, the conversion is *frozen*: relations outside ``noEvent`` become
        symbols, appended to this list (equal relations share one symbol).
    der : dict, optional
        Shared map of state name -> symbol of ``der(state)`` (filled on the way).
    """

    def __init__(
        self,
        ca: Any,
        ast: Any,
        symbols: dict[str, Any],
        where: str,
        *,
        relations: list[Relation] | None = None,
        der: dict[str, Any] | None = None,
    ) -> None:
        self.ca = ca
        self.ast = ast
        self.symbols = symbols
        self.where = where
        self.der: dict[str, Any] = {} if der is None else der
        self.relations = relations
        self._no_event = 0
        self._keys: dict[tuple[bool, str, str], Any] = {
            (r.strict, str(r.lo), str(r.hi)): r.sym for r in relations or []
        }

    def fail(self, msg: str) -> BuildError:
        """Return a :class:`BuildError` prefixed with the location."""
        return BuildError(f"{self.where}: {msg}")

    def ref_name(self, ref: Any) -> str:
        """Return the flat name of a component reference (scalars only)."""
        name = ref.name
        for idx in getattr(ref, "indices", []) or []:
            for i in idx:
                if i is not None and getattr(i, "value", None) is not None:
                    raise self.fail(f"array access {name}[...] is not supported (scalars only)")
        child = ref.child
        while child:
            c = child[0]
            name += "." + c.name
            child = c.child
        return name

    def __call__(self, node: Any) -> Any:
        """Convert one expression node into an SX expression."""
        ca, ast = self.ca, self.ast
        if isinstance(node, ast.Primary):
            v = node.value
            if isinstance(v, bool):
                return ca.SX(1.0 if v else 0.0)
            if isinstance(v, int | float):
                return ca.SX(float(v))
            raise self.fail(f"unsupported literal {v!r}")
        if isinstance(node, ast.ComponentRef):
            name = self.ref_name(node)
            if name == "time":
                return self.symbols["time"]
            if name in ("true", "false"):
                return ca.SX(1.0 if name == "true" else 0.0)
            if name not in self.symbols:
                raise self.fail(f"unknown variable '{name}'")
            return self.symbols[name]
        if isinstance(node, ast.IfExpression):
            result = self(node.expressions[-1])
            for cond, expr in zip(
                reversed(node.conditions), reversed(node.expressions[:-1]), strict=True
            ):
                result = ca.if_else(self(cond), self(expr), result)
            return result
        if isinstance(node, ast.Expression):
            return self.expression(node)
        if isinstance(node, int | float):
            return ca.SX(float(node))
        raise self.fail(f"unsupported expression node {type(node).__name__}")

    def relation(self, op: str, a: Any, b: Any, node: Any) -> Any:
        """Return the symbol of the frozen relation ``a op b`` (creating it once)."""
        swap, strict = _RELATIONS[op]
        lo, hi = (b, a) if swap else (a, b)
        key = (strict, str(lo), str(hi))
        if key not in self._keys:
            assert self.relations is not None
            sym = self.ca.SX.sym(f"c{len(self.relations)}")
            self.relations.append(Relation(sym, lo, hi, strict, expr_text(node, self.ast)))
            self._keys[key] = sym
        return self._keys[key]

    def expression(self, node: Any) -> Any:
        """Convert an operator or function application."""
        ca, ast = self.ca, self.ast
        op = node.operator
        if isinstance(op, ast.ComponentRef):
            op = self.ref_name(op)
        ops = node.operands
        if op == "der":
            return self._der(ops[0])
        if op in ("noEvent", "smooth", "homotopy"):
            inner = ops[-1] if op == "smooth" else ops[0]
            self._no_event += op == "noEvent"
            try:
                return self(inner)
            finally:
                self._no_event -= op == "noEvent"
        args = [self(o) for o in ops]
        n = len(args)
        if op == "-" and n == 1:
            return -args[0]
        if op == "+" and n == 1:
            return args[0]
        if op == "not" and n == 1:
            return ca.logic_not(args[0])
        if n == 2:
            a, b = args
            if op in _RELATIONS and self.relations is not None and not self._no_event:
                return self.relation(op, a, b, node)
            binary = {
                "+": lambda: a + b,
                "-": lambda: a - b,
                "*": lambda: a * b,
                ".*": lambda: a * b,
                "/": lambda: a / b,
                "./": lambda: a / b,
                "^": lambda: a**b,
                ".^": lambda: a**b,
                "<": lambda: a < b,
                "<=": lambda: a <= b,
                ">": lambda: a > b,
                ">=": lambda: a >= b,
                "==": lambda: a == b,
                "<>": lambda: a != b,
                "and": lambda: ca.logic_and(a, b),
                "or": lambda: ca.logic_or(a, b),
                "min": lambda: ca.fmin(a, b),
                "max": lambda: ca.fmax(a, b),
                "atan2": lambda: ca.atan2(a, b),
                "mod": lambda: a - ca.floor(a / b) * b,
                "rem": lambda: ca.fmod(a, b),
                "div": lambda: ca.if_else(a / b >= 0, ca.floor(a / b), ca.ceil(a / b)),
            }
            if op in binary:
                return binary[op]()
        if n == 1 and op in _UNARY:
            return getattr(ca, _UNARY[op])(args[0])
        raise self.fail(f"unsupported operator or function '{op}' with {n} argument(s)")

    def _der(self, arg: Any) -> Any:
        if not isinstance(arg, self.ast.ComponentRef):
            raise self.fail("der() of an expression is not supported, only der(variable)")
        name = self.ref_name(arg)
        if name not in self.symbols:
            raise self.fail(f"der() of unknown variable '{name}'")
        if name not in self.der:
            self.der[name] = self.ca.SX.sym(f"der({name})")
        return self.der[name]


def expr_text(node: Any, ast: Any) -> str:
    """Return a readable (approximate) Modelica text of an expression, for messages.

    Parameters
    ----------
    node : pymoca.ast node
        The expression.
    ast : module
        ``pymoca.ast``.

    Returns
    -------
    str
        The expression in Modelica-like syntax.
    """
    if isinstance(node, ast.Primary):
        return repr(node.value)
    if isinstance(node, ast.ComponentRef):
        return str(node)
    if isinstance(node, ast.IfExpression):
        parts = [
            f"if {expr_text(c, ast)} then {expr_text(e, ast)}"
            for c, e in zip(node.conditions, node.expressions[:-1], strict=False)
        ]
        return " else".join(parts) + f" else {expr_text(node.expressions[-1], ast)}"
    if isinstance(node, ast.Expression):
        op = node.operator
        op = str(op) if isinstance(op, ast.ComponentRef) else op
        args = [expr_text(o, ast) for o in node.operands]
        if len(args) == 2 and not op.isidentifier():
            return f"({args[0]} {op} {args[1]})"
        if len(args) == 1 and op in ("-", "+", "not"):
            return f"{op}{args[0]}"
        return f"{op}({', '.join(args)})"
    return str(node)
