"""Parse and flatten a Modelica model and turn its equations into CasADi residuals.

pymoca parses and flattens the Modelica source; everything after flattening (the
classification of variables, the residuals of the equations, the attributes that end up
in ``modelDescription.xml``) is done here, without pymoca's CasADi back end and its
``simplify`` pass.

Supported subset: one scalar ``model`` with ``Real`` variables, ``parameter``/``constant``
declarations with literal (or constant-foldable) values, ``input``/``output`` prefixes,
``der()``, arithmetic, comparison and Boolean operators, ``if``-expressions and the usual
elementary functions. Anything else raises :class:`~tsid_fmu.errors.BuildError` naming
the file, the model and the offending declaration or equation.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tsid_fmu.errors import BuildError

__all__ = ["FlatModel", "Variable", "flatten_model", "import_build_deps"]


def import_build_deps() -> tuple[Any, Any, Any, Any]:
    """Import the optional build dependencies.

    Returns
    -------
    tuple
        ``(casadi, pymoca.parser, pymoca.tree, pymoca.ast)``.

    Raises
    ------
    BuildError
        If pymoca or casadi is not installed.
    """
    try:
        import casadi
        import pymoca.ast
        import pymoca.parser
        import pymoca.tree
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise BuildError(
            f"building FMUs needs pymoca and casadi ({exc}); "
            "install them with: pip install tsid-fmu[build]"
        ) from exc
    return casadi, pymoca.parser, pymoca.tree, pymoca.ast


@dataclass
class Variable:
    """One scalar variable of the flattened model.

    Attributes
    ----------
    name : str
        Flat Modelica name.
    kind : str
        One of ``"state"``, ``"input"``, ``"output"``, ``"parameter"``, ``"local"``
        (algebraic variable that is neither input nor output).
    unit : str or None
        The ``unit`` attribute.
    description : str
        The description string of the declaration.
    start : float or None
        Start value (parameter value for parameters).
    sym : Any
        The CasADi ``SX`` symbol of the variable.
    """

    name: str
    kind: str
    unit: str | None
    description: str
    start: float | None
    sym: Any = None


@dataclass
class FlatModel:
    """A flattened, scalar Modelica model ready for causalization.

    Attributes
    ----------
    name : str
        Fully qualified model name (e.g. ``"TSID.LSEA_SISO"``).
    description : str
        Description string of the model.
    source : Path
        The Modelica file the model was read from.
    states, inputs, outputs, parameters, locals : list of Variable
        Variables by role, in declaration order.
    der_syms : list
        CasADi symbols standing for ``der(state)``, in the order of ``states``.
    time : Any
        CasADi symbol of ``time``.
    residuals : list
        One CasADi ``SX`` residual ``lhs - rhs`` per equation.
    equation_text : list of str
        A readable form of each equation, for error messages.
    experiment : dict
        ``StartTime``, ``StopTime``, ``Interval`` read from ``annotation(experiment(...))``
        when present.
    info_html : str
        The ``Documentation(info=...)`` text, if any.
    """

    name: str
    description: str
    source: Path
    states: list[Variable] = field(default_factory=list)
    inputs: list[Variable] = field(default_factory=list)
    outputs: list[Variable] = field(default_factory=list)
    parameters: list[Variable] = field(default_factory=list)
    locals: list[Variable] = field(default_factory=list)
    der_syms: list[Any] = field(default_factory=list)
    time: Any = None
    residuals: list[Any] = field(default_factory=list)
    equation_text: list[str] = field(default_factory=list)
    experiment: dict[str, float] = field(default_factory=dict)
    info_html: str = ""

    @property
    def short_name(self) -> str:
        """Last component of the qualified name (used as FMI model identifier)."""
        return self.name.rsplit(".", 1)[-1]


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


class _Converter:
    """Convert pymoca expression trees into CasADi SX expressions."""

    def __init__(self, ca: Any, ast: Any, symbols: dict[str, Any], where: str) -> None:
        self.ca = ca
        self.ast = ast
        self.symbols = symbols
        self.where = where
        self.der: dict[str, Any] = {}

    def fail(self, msg: str) -> BuildError:
        return BuildError(f"{self.where}: {msg}")

    def ref_name(self, ref: Any) -> str:
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

    def expression(self, node: Any) -> Any:
        ca, ast = self.ca, self.ast
        op = node.operator
        if isinstance(op, ast.ComponentRef):
            op = self.ref_name(op)
        ops = node.operands
        if op == "der":
            arg = ops[0]
            if not isinstance(arg, ast.ComponentRef):
                raise self.fail("der() of an expression is not supported, only der(variable)")
            name = self.ref_name(arg)
            if name not in self.symbols:
                raise self.fail(f"der() of unknown variable '{name}'")
            if name not in self.der:
                self.der[name] = ca.SX.sym(f"der({name})")
            return self.der[name]
        if op in ("noEvent", "smooth", "homotopy"):
            return self(ops[-1] if op == "smooth" else ops[0])
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


def _expr_text(node: Any, ast: Any) -> str:
    """Readable (approximate) Modelica text of an expression, for messages."""
    if isinstance(node, ast.Primary):
        return repr(node.value)
    if isinstance(node, ast.ComponentRef):
        return str(node)
    if isinstance(node, ast.IfExpression):
        parts = [
            f"if {_expr_text(c, ast)} then {_expr_text(e, ast)}"
            for c, e in zip(node.conditions, node.expressions[:-1], strict=False)
        ]
        return " else".join(parts) + f" else {_expr_text(node.expressions[-1], ast)}"
    if isinstance(node, ast.Expression):
        op = node.operator
        op = str(op) if isinstance(op, ast.ComponentRef) else op
        args = [_expr_text(o, ast) for o in node.operands]
        if len(args) == 2 and not op.isidentifier():
            return f"({args[0]} {op} {args[1]})"
        if len(args) == 1 and op in ("-", "+", "not"):
            return f"{op}{args[0]}"
        return f"{op}({', '.join(args)})"
    return str(node)


def _literal(value: Any, ast: Any) -> Any:
    """Return the Python value of a pymoca literal attribute (or ``None``)."""
    if isinstance(value, ast.Primary):
        return value.value
    if isinstance(value, int | float | str | bool) or value is None:
        return value
    return value


def _find_class(root: Any, name: str) -> Any:
    """Find a class by (qualified or short) name in a parsed tree."""
    parts = name.split(".")
    node = root
    ok = True
    for p in parts:
        if p in getattr(node, "classes", {}):
            node = node.classes[p]
        else:
            ok = False
            break
    if ok:
        return node

    found: list[Any] = []

    def walk(c: Any, prefix: str) -> None:
        for k, sub in getattr(c, "classes", {}).items():
            full = f"{prefix}.{k}" if prefix else k
            if full.endswith("." + name) or full == name:
                found.append((full, sub))
            walk(sub, full)

    walk(root, "")
    if len(found) == 1:
        return found[0][1]
    return None


def _qualified_name(root: Any, cls: Any) -> str:
    for k, sub in root.classes.items():
        if sub is cls:
            return k
        inner = _qualified_name(sub, cls) if getattr(sub, "classes", None) else ""
        if inner:
            return f"{k}.{inner}"
    return ""


_EXPERIMENT_RE = re.compile(r"experiment\s*\(([^)]*)\)", re.S)
_INFO_RE = re.compile(r'info\s*=\s*"((?:[^"\\]|\\.)*)"', re.S)


def _annotations(text: str) -> tuple[dict[str, float], str]:
    """Read ``experiment(...)`` and ``Documentation(info=...)`` from the source text."""
    experiment: dict[str, float] = {}
    m = _EXPERIMENT_RE.search(text)
    if m:
        for key, val in re.findall(r"(\w+)\s*=\s*([-+0-9.eE]+)", m.group(1)):
            try:
                experiment[key] = float(val)
            except ValueError:
                continue
    info = ""
    m = _INFO_RE.search(text)
    if m:
        info = m.group(1).replace('\\"', '"')
    return experiment, info


def flatten_model(
    model_file: str | Path, model_name: str, package_dir: str | Path | None = None
) -> FlatModel:
    """Parse, flatten and convert one Modelica model.

    Parameters
    ----------
    model_file : str or Path
        The ``.mo`` file holding the model.
    model_name : str
        Qualified (``"TSID.LSEA_SISO"``) or short (``"LSEA_SISO"``) model name.
    package_dir : str or Path, optional
        A package directory whose other ``.mo`` files are parsed as well (for models that
        refer to other classes of their package). By default only ``model_file`` is read.

    Returns
    -------
    FlatModel
        Variables by role with their attributes and one residual per equation.

    Raises
    ------
    BuildError
        If the file cannot be read or parsed, the model is not found or uses a
        construct outside the supported subset.
    """
    ca, parser, tree, ast = import_build_deps()
    model_file = Path(model_file)
    try:
        text = model_file.read_text(encoding="utf-8")
    except OSError as exc:
        raise BuildError(f"cannot read Modelica file {model_file}: {exc}") from exc
    where = f"{model_file}: model {model_name}"
    try:
        root = parser.parse(text, bypass_cache=True)
    except Exception as exc:
        raise BuildError(f"{model_file}: Modelica parse error: {exc}") from exc
    if root is None:
        raise BuildError(f"{model_file}: Modelica parse error (no class found)")
    if package_dir is not None:
        for extra in sorted(Path(package_dir).rglob("*.mo")):
            if extra.resolve() == model_file.resolve():
                continue
            try:
                other = parser.parse(extra.read_text(encoding="utf-8"), bypass_cache=True)
            except Exception as exc:
                raise BuildError(f"{extra}: Modelica parse error: {exc}") from exc
            if other is not None:
                root.extend(other)

    cls = _find_class(root, model_name)
    if cls is None:
        raise BuildError(f"{model_file}: model '{model_name}' not found")
    qname = _qualified_name(root, cls) or model_name
    where = f"{model_file}: model {qname}"
    try:
        flat_root = tree.flatten(root, ast.ComponentRef.from_string(qname))
    except Exception as exc:
        raise BuildError(f"{where}: flattening failed: {exc}") from exc
    flat = flat_root.classes[qname] if qname in flat_root.classes else flat_root
    for attr, what in (
        ("initial_equations", "initial equations"),
        ("statements", "algorithm sections"),
        ("initial_statements", "initial algorithm sections"),
    ):
        if getattr(flat, attr, None):
            raise BuildError(f"{where}: {what} are not supported")

    experiment, info = _annotations(text)
    fm = FlatModel(
        name=qname,
        description=flat.comment or "",
        source=model_file,
        experiment=experiment,
        info_html=info,
    )
    fm.time = ca.SX.sym("time")

    # -- declarations -------------------------------------------------------------
    symbols: dict[str, Any] = {"time": fm.time}
    decls: list[tuple[str, Any]] = list(flat.symbols.items())
    constants: dict[str, Any] = {}
    variables: list[Variable] = []
    for name, s in decls:
        if name == "time":
            raise BuildError(f"{where}: a variable must not be called 'time'")
        tname = s.type if isinstance(s.type, str) else getattr(s.type, "name", str(s.type))
        if tname != "Real":
            raise BuildError(f"{where}: variable '{name}' has type {tname}; only Real is supported")
        dims = s.dimensions
        if dims and any(
            d is not None and getattr(d, "value", None) not in (None, 1) for dd in dims for d in dd
        ):
            raise BuildError(f"{where}: variable '{name}' is an array; only scalars are supported")
        prefixes = set(s.prefixes or [])
        if "discrete" in prefixes:
            raise BuildError(f"{where}: discrete variable '{name}' is not supported")
        unit = _literal(s.unit, ast)
        unit = unit if isinstance(unit, str) and unit else None
        desc = s.comment or ""
        start = _literal(s.start, ast)
        value = _literal(s.value, ast)
        if "constant" in prefixes or "parameter" in prefixes:
            raw = s.value if value is not None else s.start
            if raw is None or (isinstance(raw, ast.Primary) and raw.value is None):
                raise BuildError(f"{where}: parameter '{name}' has no value")
            conv = _Converter(ca, ast, {**constants, "time": fm.time}, f"{where}: '{name}'")
            expr = conv(raw)
            if not expr.is_constant():
                raise BuildError(
                    f"{where}: the value of parameter '{name}' is not a literal "
                    "(bindings to other parameters are not supported)"
                )
            num = float(ca.evalf(expr))
            if "constant" in prefixes:
                constants[name] = ca.SX(num)
                symbols[name] = ca.SX(num)
                continue
            var = Variable(name, "parameter", unit, desc, num, ca.SX.sym(name))
        else:
            st = None
            if start is not None and not isinstance(start, str):
                try:
                    st = float(start)
                except (TypeError, ValueError):
                    conv = _Converter(ca, ast, {**constants, "time": fm.time}, where)
                    e = conv(s.start)
                    if not e.is_constant():
                        raise BuildError(
                            f"{where}: start value of '{name}' must be a literal"
                        ) from None
                    st = float(ca.evalf(e))
            kind = "input" if "input" in prefixes else "output" if "output" in prefixes else "local"
            var = Variable(name, kind, unit, desc, st, ca.SX.sym(name))
        variables.append(var)
        symbols[name] = var.sym

    # -- equations ----------------------------------------------------------------
    conv = _Converter(ca, ast, symbols, where)
    for i, eq in enumerate(flat.equations, start=1):
        if not isinstance(eq, ast.Equation):
            raise BuildError(
                f"{where}: equation {i} is a {type(eq).__name__}; only simple equations "
                "'lhs = rhs' are supported"
            )
        txt = f"{_expr_text(eq.left, ast)} = {_expr_text(eq.right, ast)}"
        conv.where = f"{where}: equation {i} '{txt}'"
        res = conv(eq.left) - conv(eq.right)
        fm.residuals.append(res)
        fm.equation_text.append(txt)

    # -- roles --------------------------------------------------------------------
    for var in variables:
        if var.kind in ("local", "output") and var.name in conv.der:
            if var.kind == "output":
                raise BuildError(
                    f"{where}: output '{var.name}' is differentiated; declare a separate "
                    "state and an output equation"
                )
            var.kind = "state"
            if var.start is None:
                var.start = 0.0
        if var.kind == "input":
            if var.name in conv.der:
                raise BuildError(f"{where}: der() of input '{var.name}' is not supported")
            if var.start is None:
                var.start = 0.0
    for var in variables:
        {
            "state": fm.states,
            "input": fm.inputs,
            "output": fm.outputs,
            "parameter": fm.parameters,
            "local": fm.locals,
        }[var.kind].append(var)
    fm.der_syms = [conv.der[v.name] for v in fm.states]
    for v in fm.parameters + fm.states + fm.inputs:
        if v.start is not None and not math.isfinite(v.start):
            raise BuildError(f"{where}: start value of '{v.name}' is not finite")
    return fm
