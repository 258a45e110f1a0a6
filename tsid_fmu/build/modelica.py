"""Parse and flatten a Modelica model and turn its equations into CasADi residuals.

pymoca parses and flattens the Modelica source; everything after flattening (the
classification of variables, the residuals of the equations, the attributes that end up
in ``modelDescription.xml``) is done here, without pymoca's CasADi back end and its
``simplify`` pass.

Supported subset: one scalar ``model`` with ``Real`` variables and ``Integer`` parameters,
``parameter``/``constant`` declarations with literal (or constant-foldable) values,
``input``/``output`` prefixes, ``der()``, arithmetic, comparison and Boolean operators,
``if``-expressions and the usual elementary functions. A state's initial value may be an
expression of parameters, given as its ``start`` (``Real x(start = x0, fixed = true)``)
or by an ``initial equation`` ``x = <expression of parameters>``; the FMU computes it
from the parameter values at initialisation. Anything else raises
:class:`~tsid_fmu.errors.BuildError` naming the file, the model, the line and the
offending declaration or equation.
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

from tsid_fmu.errors import BuildError

from .expressions import Converter, expr_text
from .flat import FlatModel, Variable, import_build_deps
from .sourcelines import SourceLines, at_line

__all__ = ["FlatModel", "SourceLines", "Variable", "at_line", "flatten_model", "import_build_deps"]


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


def _parse_flat(
    model_file: Path, model_name: str, package_dir: str | Path | None
) -> tuple[str, Any, str, str, SourceLines]:
    """Parse the source (and its package) and flatten the model.

    Returns the source text, the flat class, its qualified name, the message prefix and
    the line numbers of the model's declarations and equations.
    """
    _ca, parser, tree, ast = import_build_deps()
    try:
        text = model_file.read_text(encoding="utf-8")
    except OSError as exc:
        raise BuildError(f"cannot read Modelica file {model_file}: {exc}") from exc
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
    lines = SourceLines(text, qname.rsplit(".", 1)[-1])
    for attr, what, initial in (
        ("statements", "algorithm sections", False),
        ("initial_statements", "initial algorithm sections", True),
    ):
        if getattr(flat, attr, None):
            at = at_line(where, lines.section("algorithm", initial))
            raise BuildError(f"{at}: {what} are not supported (write the assignments as equations)")
    return text, flat, qname, where, lines


def _supported(name: str, s: Any, w: str) -> tuple[str, set[str]]:
    """Return a declaration's type name and prefixes; refuse what the build cannot take."""
    tname = s.type if isinstance(s.type, str) else getattr(s.type, "name", str(s.type))
    prefixes = set(s.prefixes or [])
    is_param = bool(prefixes & {"parameter", "constant"})
    if tname != "Real" and not (tname == "Integer" and is_param):
        raise BuildError(
            f"{w}: variable '{name}' has type {tname}; only Real is supported "
            "(and Integer parameters)"
        )
    dims = s.dimensions
    if dims and any(
        d is not None and getattr(d, "value", None) not in (None, 1) for dd in dims for d in dd
    ):
        raise BuildError(f"{w}: variable '{name}' is an array; only scalars are supported")
    if "discrete" in prefixes:
        raise BuildError(f"{w}: discrete variable '{name}' is not supported")
    return tname, prefixes


def _declarations(
    flat: Any, time: Any, where: str, lines: SourceLines
) -> tuple[list[Variable], dict[str, Any]]:
    """Variables (with symbols) and the symbol table of the flat class's declarations.

    A ``start`` that is not a literal may be an expression of parameters and constants
    (declared anywhere in the model): it becomes :attr:`Variable.init`, and ``start``
    its value at the parameters' values.
    """
    ca, _parser, _tree, ast = import_build_deps()
    symbols: dict[str, Any] = {"time": time}
    decls: list[tuple[str, Any]] = list(flat.symbols.items())
    constants: dict[str, Any] = {}
    variables: list[Variable] = []
    pending: list[tuple[Variable, Any, str]] = []
    for name, s in decls:
        w = at_line(where, lines.declaration(name))
        if name == "time":
            raise BuildError(f"{w}: a variable must not be called 'time'")
        tname, prefixes = _supported(name, s, w)
        unit = _literal(s.unit, ast)
        unit = unit if isinstance(unit, str) and unit else None
        desc = s.comment or ""
        start = _literal(s.start, ast)
        value = _literal(s.value, ast)
        if "constant" in prefixes or "parameter" in prefixes:
            raw = s.value if value is not None else s.start
            if raw is None or (isinstance(raw, ast.Primary) and raw.value is None):
                raise BuildError(f"{w}: parameter '{name}' has no value")
            conv = Converter(ca, ast, {**constants, "time": time}, f"{w}: '{name}'")
            expr = conv(raw)
            if not expr.is_constant():
                raise BuildError(
                    f"{w}: the value of parameter '{name}' is not a literal "
                    "(bindings to other parameters are not supported)"
                )
            num = float(ca.evalf(expr))
            if tname == "Integer" and not (num == int(num) and abs(num) < 2**31):
                raise BuildError(f"{w}: Integer parameter '{name}' has the value {num}")
            if "constant" in prefixes:
                constants[name] = ca.SX(num)
                symbols[name] = ca.SX(num)
                continue
            var = Variable(name, "parameter", unit, desc, num, ca.SX.sym(name))
            var.integer = tname == "Integer"
        else:
            st, expression = None, False
            if start is not None and not isinstance(start, str):
                try:
                    st = float(start)
                except (TypeError, ValueError):
                    expression = True
            kind = "input" if "input" in prefixes else "output" if "output" in prefixes else "local"
            var = Variable(name, kind, unit, desc, st, ca.SX.sym(name))
            var.fixed = _literal(getattr(s, "fixed", None), ast) is True
            if expression:  # converted once every parameter is known
                pending.append((var, s.start, f"{w}: start value of '{name}'"))
        var.line = lines.declaration(name)
        variables.append(var)
        symbols[name] = var.sym
    params = [v for v in variables if v.kind == "parameter"]
    for var, raw, what in pending:
        var.init = _parameter_expression(raw, symbols, params, what)
        var.start = _at_defaults(var.init, params)
        if not math.isfinite(var.start):
            raise BuildError(f"{what} is not finite at the parameters' values")
        if var.init.is_constant():
            var.init = None
    return variables, symbols


def _parameter_expression(
    raw: Any, table: dict[str, Any], params: list[Variable], what: str
) -> Any:
    """Convert ``raw`` to CasADi and check that it depends on parameters only.

    Parameters
    ----------
    raw : pymoca expression
        The expression.
    table : dict
        The names it may use (constants, parameters; others are reported as unknown).
    params : list of Variable
        The parameters.
    what : str
        Message prefix naming the place (file, model, line and what the expression is).

    Returns
    -------
    casadi.SX
        The expression.

    Raises
    ------
    BuildError
        If it uses anything but parameters and constants.
    """
    ca, _parser, _tree, ast = import_build_deps()
    conv = Converter(ca, ast, table, what)
    expr = ca.SX(conv(raw))
    names = {p.name for p in params}
    for sym in ca.symvar(expr):
        if sym.name() not in names:
            raise BuildError(
                f"{what} depends on '{sym.name()}'; only parameters and constants may appear"
            )
    return expr


def _at_defaults(expr: Any, params: list[Variable]) -> float:
    """Value of a parameter expression at the parameters' ``start``."""
    ca, *_ = import_build_deps()
    if params:
        expr = ca.substitute(
            ca.SX(expr),
            ca.vertcat(*[p.sym for p in params]),
            ca.vertcat(*[float(p.start) for p in params]),
        )
    return float(ca.evalf(expr))


def _equations(
    flat: Any, fm: FlatModel, symbols: dict[str, Any], where: str, lines: SourceLines
) -> dict[str, Any]:
    """Fill the residuals (live and frozen) of ``fm``; return the ``der()`` symbols."""
    ca, _parser, _tree, ast = import_build_deps()
    conv = Converter(ca, ast, symbols, where)
    frozen = Converter(ca, ast, symbols, where, relations=fm.relations, der=conv.der)
    for i, eq in enumerate(flat.equations, start=1):
        at = at_line(where, lines.equation(i - 1, count=len(flat.equations)))
        if not isinstance(eq, ast.Equation):
            raise BuildError(
                f"{at}: equation {i} is a {type(eq).__name__}; only simple equations "
                "'lhs = rhs' are supported"
            )
        txt = f"{expr_text(eq.left, ast)} = {expr_text(eq.right, ast)}"
        conv.where = f"{at}: equation {i} '{txt}'"
        res = conv(eq.left) - conv(eq.right)
        fm.residuals.append(res)
        frozen.where = conv.where
        fm.residuals_frozen.append(frozen(eq.left) - frozen(eq.right))
        fm.equation_text.append(txt)
        fm.equation_lines.append(lines.equation(i - 1, count=len(flat.equations)))
    return conv.der


def _assign_roles(
    fm: FlatModel, variables: list[Variable], der: dict[str, Any], where: str
) -> None:
    """Sort the variables of ``fm`` by role; differentiated locals become states.

    A parameter-dependent ``start`` of a state is its computed initial value; of an
    algebraic variable only an iteration start (its value at the parameters' values); of
    an input it is refused.
    """
    for var in variables:
        w = at_line(where, var.line)
        if var.kind in ("local", "output") and var.name in der:
            if var.kind == "output":
                raise BuildError(
                    f"{w}: output '{var.name}' is differentiated; declare a separate "
                    "state and an output equation"
                )
            var.kind = "state"
            if var.start is None:
                var.start = 0.0
        elif var.init is not None:
            if var.kind == "input":
                raise BuildError(
                    f"{w}: the start value of input '{var.name}' depends on parameters; "
                    "an input's start must be a literal"
                )
            var.init = None
        if var.kind == "input":
            if var.name in der:
                raise BuildError(f"{w}: der() of input '{var.name}' is not supported")
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
    fm.der_syms = [der[v.name] for v in fm.states]
    for v in fm.parameters + fm.states + fm.inputs:
        if v.start is not None and not math.isfinite(v.start):
            raise BuildError(f"{where}: start value of '{v.name}' is not finite")


def _initial_equations(
    flat: Any, fm: FlatModel, symbols: dict[str, Any], where: str, lines: SourceLines
) -> None:
    """Apply the ``initial equation`` sections: ``state = <expression of parameters>``.

    Each sets :attr:`Variable.init` (and ``start``, its value at the parameters' values)
    of one state; either side may be the state. Anything else is refused with the
    equation and its line.
    """
    _ca, _parser, _tree, ast = import_build_deps()
    states = {v.name: v for v in fm.states}
    others = {v.name for v in fm.inputs + fm.outputs + fm.locals + fm.parameters}
    set_at: dict[str, int | None] = {}
    form = "only 'state = expression of parameters' (e.g. 'x = x0') is supported"
    initial_equations = getattr(flat, "initial_equations", None) or []
    for i, eq in enumerate(initial_equations):
        line = lines.equation(i, initial=True, count=len(initial_equations))
        at = at_line(where, line)
        if not isinstance(eq, ast.Equation):
            raise BuildError(f"{at}: initial equation {i + 1} is a {type(eq).__name__}; {form}")
        txt = f"{expr_text(eq.left, ast)} = {expr_text(eq.right, ast)}"

        def name_of(node: Any) -> str | None:
            if isinstance(node, ast.ComponentRef) and not getattr(node, "child", None):
                return node.name
            return None

        left, right = name_of(eq.left), name_of(eq.right)
        if left in states:
            target, expr = left, eq.right
        elif right in states:
            target, expr = right, eq.left
        elif left in others or right in others:
            name = left if left in others else right
            raise BuildError(
                f"{at}: initial equation '{txt}' sets '{name}', which is not a state; {form}"
            )
        else:
            raise BuildError(f"{at}: initial equation '{txt}' is not supported; {form}")
        var = states[target]
        if target in set_at:
            first = set_at[target]
            raise BuildError(
                f"{at}: initial equation '{txt}' sets state '{target}' a second time"
                + (f" (first at line {first})" if first else "")
            )
        if var.fixed:
            raise BuildError(
                f"{at}: initial equation '{txt}' sets state '{target}', whose declaration"
                + (f" (line {var.line})" if var.line else "")
                + " has fixed = true: its initial value would be given twice"
            )
        set_at[target] = line
        what = f"{at}: initial equation '{txt}': the value of '{target}'"
        var.init = _parameter_expression(expr, symbols, fm.parameters, what)
        var.start = _at_defaults(var.init, fm.parameters)
        if not math.isfinite(var.start):
            raise BuildError(f"{what} is not finite at the parameters' values")
        if var.init.is_constant():
            var.init = None


def flatten_model(
    model_file: str | Path, model_name: str, package_dir: str | Path | None = None
) -> FlatModel:
    """Parse, flatten and convert one Modelica model.

    Parameters
    ----------
    model_file, model_name, package_dir
        As for :func:`~tsid_fmu.build.build_fmu`; without ``package_dir`` only
        ``model_file`` is read.

    Returns
    -------
    FlatModel
        Variables by role with their attributes and one residual per equation (live and
        with the relations frozen, see :mod:`.expressions`).

    Raises
    ------
    BuildError
        If the file cannot be read or parsed, the model is not found or uses a
        construct outside the supported subset.
    """
    ca, *_ = import_build_deps()
    model_file = Path(model_file)
    text, flat, qname, where, lines = _parse_flat(model_file, model_name, package_dir)
    experiment, info = _annotations(text)
    fm = FlatModel(
        name=qname,
        description=flat.comment or "",
        source=model_file,
        experiment=experiment,
        info_html=info,
        lines=lines,
    )
    fm.time = ca.SX.sym("time")
    variables, symbols = _declarations(flat, fm.time, where, lines)
    der = _equations(flat, fm, symbols, where, lines)
    _assign_roles(fm, variables, der, where)
    _initial_equations(flat, fm, symbols, where, lines)
    return fm
