"""Parse and flatten a Modelica model and turn its equations into CasADi residuals.

pymoca parses and flattens the Modelica source; everything after flattening (the
classification of variables, the residuals of the equations, the attributes that end up
in ``modelDescription.xml``) is done here, without pymoca's CasADi back end and its
``simplify`` pass.

Supported subset: one scalar ``model`` with ``Real`` variables and ``Integer`` parameters,
``parameter``/``constant`` declarations with literal (or constant-foldable) values,
``input``/``output`` prefixes, ``der()``, arithmetic, comparison and Boolean operators,
``if``-expressions and the usual elementary functions. Anything else raises
:class:`~tsid_fmu.errors.BuildError` naming the file, the model and the offending
declaration or equation.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tsid_fmu.errors import BuildError

from .expressions import Converter, Relation, expr_text

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
    integer : bool
        An ``Integer`` parameter (a structural switch: FMI ``Integer``/``Int32``).
    """

    name: str
    kind: str
    unit: str | None
    description: str
    start: float | None
    sym: Any = None
    integer: bool = False


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
        One CasADi ``SX`` residual ``lhs - rhs`` per equation (relations evaluated live).
    residuals_frozen : list
        The same residuals with every relation outside ``noEvent`` replaced by the
        symbol of its :class:`~.expressions.Relation` (the Model Exchange form).
    relations : list of Relation
        The relations that generate state events, in order of appearance.
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
    residuals_frozen: list[Any] = field(default_factory=list)
    relations: list[Relation] = field(default_factory=list)
    equation_text: list[str] = field(default_factory=list)
    experiment: dict[str, float] = field(default_factory=dict)
    info_html: str = ""

    @property
    def short_name(self) -> str:
        """Last component of the qualified name (used as FMI model identifier)."""
        return self.name.rsplit(".", 1)[-1]


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
) -> tuple[str, Any, str, str]:
    """Parse the source (and its package) and flatten the model.

    Returns the source text, the flat class, its qualified name and the message prefix.
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
    for attr, what in (
        ("initial_equations", "initial equations"),
        ("statements", "algorithm sections"),
        ("initial_statements", "initial algorithm sections"),
    ):
        if getattr(flat, attr, None):
            raise BuildError(f"{where}: {what} are not supported")
    return text, flat, qname, where


def _declarations(flat: Any, time: Any, where: str) -> tuple[list[Variable], dict[str, Any]]:
    """Variables (with symbols) and the symbol table of the flat class's declarations."""
    ca, _parser, _tree, ast = import_build_deps()
    symbols: dict[str, Any] = {"time": time}
    decls: list[tuple[str, Any]] = list(flat.symbols.items())
    constants: dict[str, Any] = {}
    variables: list[Variable] = []
    for name, s in decls:
        if name == "time":
            raise BuildError(f"{where}: a variable must not be called 'time'")
        tname = s.type if isinstance(s.type, str) else getattr(s.type, "name", str(s.type))
        prefixes = set(s.prefixes or [])
        is_param = bool(prefixes & {"parameter", "constant"})
        if tname != "Real" and not (tname == "Integer" and is_param):
            raise BuildError(
                f"{where}: variable '{name}' has type {tname}; only Real is supported "
                "(and Integer parameters)"
            )
        dims = s.dimensions
        if dims and any(
            d is not None and getattr(d, "value", None) not in (None, 1) for dd in dims for d in dd
        ):
            raise BuildError(f"{where}: variable '{name}' is an array; only scalars are supported")
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
            conv = Converter(ca, ast, {**constants, "time": time}, f"{where}: '{name}'")
            expr = conv(raw)
            if not expr.is_constant():
                raise BuildError(
                    f"{where}: the value of parameter '{name}' is not a literal "
                    "(bindings to other parameters are not supported)"
                )
            num = float(ca.evalf(expr))
            if tname == "Integer" and not (num == int(num) and abs(num) < 2**31):
                raise BuildError(f"{where}: Integer parameter '{name}' has the value {num}")
            if "constant" in prefixes:
                constants[name] = ca.SX(num)
                symbols[name] = ca.SX(num)
                continue
            var = Variable(name, "parameter", unit, desc, num, ca.SX.sym(name))
            var.integer = tname == "Integer"
        else:
            st = None
            if start is not None and not isinstance(start, str):
                try:
                    st = float(start)
                except (TypeError, ValueError):
                    conv = Converter(ca, ast, {**constants, "time": time}, where)
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
    return variables, symbols


def _equations(flat: Any, fm: FlatModel, symbols: dict[str, Any], where: str) -> dict[str, Any]:
    """Fill the residuals (live and frozen) of ``fm``; return the ``der()`` symbols."""
    ca, _parser, _tree, ast = import_build_deps()
    conv = Converter(ca, ast, symbols, where)
    frozen = Converter(ca, ast, symbols, where, relations=fm.relations, der=conv.der)
    for i, eq in enumerate(flat.equations, start=1):
        if not isinstance(eq, ast.Equation):
            raise BuildError(
                f"{where}: equation {i} is a {type(eq).__name__}; only simple equations "
                "'lhs = rhs' are supported"
            )
        txt = f"{expr_text(eq.left, ast)} = {expr_text(eq.right, ast)}"
        conv.where = f"{where}: equation {i} '{txt}'"
        res = conv(eq.left) - conv(eq.right)
        fm.residuals.append(res)
        frozen.where = conv.where
        fm.residuals_frozen.append(frozen(eq.left) - frozen(eq.right))
        fm.equation_text.append(txt)
    return conv.der


def _assign_roles(
    fm: FlatModel, variables: list[Variable], der: dict[str, Any], where: str
) -> None:
    """Sort the variables of ``fm`` by role; differentiated locals become states."""
    for var in variables:
        if var.kind in ("local", "output") and var.name in der:
            if var.kind == "output":
                raise BuildError(
                    f"{where}: output '{var.name}' is differentiated; declare a separate "
                    "state and an output equation"
                )
            var.kind = "state"
            if var.start is None:
                var.start = 0.0
        if var.kind == "input":
            if var.name in der:
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
    fm.der_syms = [der[v.name] for v in fm.states]
    for v in fm.parameters + fm.states + fm.inputs:
        if v.start is not None and not math.isfinite(v.start):
            raise BuildError(f"{where}: start value of '{v.name}' is not finite")


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
    text, flat, qname, where = _parse_flat(model_file, model_name, package_dir)
    experiment, info = _annotations(text)
    fm = FlatModel(
        name=qname,
        description=flat.comment or "",
        source=model_file,
        experiment=experiment,
        info_html=info,
    )
    fm.time = ca.SX.sym("time")
    variables, symbols = _declarations(flat, fm.time, where)
    der = _equations(flat, fm, symbols, where)
    _assign_roles(fm, variables, der, where)
    return fm
