"""Sort and solve the flattened equations for the derivatives and algebraic variables.

The residuals ``r(der(x), w; t, x, u, p) = 0`` of a :class:`~.modelica.FlatModel` are
sorted into blocks (maximum matching and strongly connected components, i.e. a BLT
decomposition). A scalar block whose residual is affine in its unknown is solved
symbolically; any other block (an algebraic loop or a nonlinear equation) is solved at
run time by CasADi's ``fast_newton`` root finder, which CasADi can generate C code for.

Two forms are built from the same model:

* the *live* form (Co-Simulation outputs): ``ode(t, x, u, p) -> der(x)``,
  ``eval(t, x, u, p) -> (der(x), w)`` and ``zc(t, x, u, p) -> z``, the relations
  evaluated wherever the functions are;
* the *frozen* form (Model Exchange and the Co-Simulation integrator, ``frozen=True``):
  the same functions with a fifth argument ``c``, the values (0 or 1) of the model's
  relations, which are discrete states changed only at events, and
  ``rel(t, x, u, p, c) -> (z, s)``, one event indicator ``z_k = hi_k - lo_k`` per
  relation ``lo_k < hi_k`` (or ``<=``) and its scale ``s_k = |lo_k| + |hi_k|`` for the
  hysteresis.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from tsid_fmu.errors import BuildError

from .expressions import Relation
from .modelica import FlatModel, Variable, import_build_deps

__all__ = ["Causalized", "Layout", "causalize"]


@dataclass
class Layout:
    """Value-reference layout of the FMU's real variables.

    The FMU keeps all reals in one array; a value reference is the index into it, in the
    order: states, derivatives, inputs, outputs, parameters, locals, then the
    wrapper's own parameter ``fixedStepSize``.
    """

    states: list[Variable]
    inputs: list[Variable]
    outputs: list[Variable]
    parameters: list[Variable]
    locals: list[Variable]

    @property
    def nx(self) -> int:
        """Number of continuous states."""
        return len(self.states)

    @property
    def x_off(self) -> int:
        """Offset of the states."""
        return 0

    @property
    def dx_off(self) -> int:
        """Offset of the state derivatives."""
        return self.nx

    @property
    def u_off(self) -> int:
        """Offset of the inputs."""
        return 2 * self.nx

    @property
    def y_off(self) -> int:
        """Offset of the algebraic variables (outputs first, then locals)."""
        return self.u_off + len(self.inputs)

    @property
    def p_off(self) -> int:
        """Offset of the parameters."""
        return self.y_off + len(self.outputs) + len(self.locals)

    @property
    def h_vr(self) -> int:
        """Value reference of ``fixedStepSize``."""
        return self.p_off + len(self.parameters)

    @property
    def n_real(self) -> int:
        """Total number of real variables."""
        return self.h_vr + 1


@dataclass
class Causalized:
    """Explicit form of a model.

    Attributes
    ----------
    ode : casadi.Function
        ``(t, x, u, p[, c]) -> der(x)``.
    eval : casadi.Function
        ``(t, x, u, p[, c]) -> (der(x), w)`` with ``w = [outputs, locals]``.
    layout : Layout
        Variable layout.
    n_implicit : int
        Number of blocks solved by Newton iteration at run time.
    zc : casadi.Function or None
        Live form: ``(t, x, u, p) -> z``, one indicator per distinct relation ``a < b`` /
        ``a <= b`` in the explicit equations (``z = b - a``; the relation holds when
        ``z > 0``, resp. ``z >= 0``). ``None`` if there are none, and for implicit models.
    rel : casadi.Function or None
        Frozen form: ``(t, x, u, p, c) -> (z, s)`` for ``relations``; ``None`` otherwise.
    relations : list of Relation
        Frozen form: the relations that are discrete states (empty in the live form).
    """

    ode: Any
    eval: Any
    layout: Layout
    n_implicit: int
    zc: Any = None
    rel: Any = None
    relations: list[Relation] = field(default_factory=list)


def _relations(ca: Any, exprs: list[Any]) -> list[Any]:
    """Distinct relations ``a < b``, ``a <= b`` in SX expressions, as indicators ``b - a``."""
    seen: set[int] = set()
    found: dict[str, Any] = {}
    stack = [e for e in exprs]
    while stack:
        e = stack.pop()
        h = e.element_hash()
        if h in seen:
            continue
        seen.add(h)
        if e.is_op(ca.OP_LT) or e.is_op(ca.OP_LE):
            ind = ca.simplify(e.dep(1) - e.dep(0))
            if not ind.is_constant():
                key = str(ind)
                if key not in found and str(-ind) not in found:
                    found[key] = ind
        for i in range(e.n_dep()):
            stack.append(e.dep(i))
    return list(found.values())


def _tarjan(n: int, succ: list[list[int]]) -> list[list[int]]:
    """Strongly connected components, dependencies first (iterative Tarjan)."""
    index = [-1] * n
    low = [0] * n
    on_stack = [False] * n
    stack: list[int] = []
    comps: list[list[int]] = []
    counter = 0
    for root in range(n):
        if index[root] >= 0:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = counter
                counter += 1
                stack.append(v)
                on_stack[v] = True
            recurse = False
            for j in range(i, len(succ[v])):
                w = succ[v][j]
                if index[w] < 0:
                    work.append((v, j + 1))
                    work.append((w, 0))
                    recurse = True
                    break
                if on_stack[w]:
                    low[v] = min(low[v], index[w])
            if recurse:
                continue
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    comp.append(w)
                    if w == v:
                        break
                comps.append(sorted(comp))
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[v])
    return comps


def _blocks(
    model: FlatModel, residuals: list[Any], unknowns: list[Any], unknown_names: list[str]
) -> tuple[list[list[int]], Any]:
    """BLT decomposition: blocks of equation indices in solve order, and the matching."""
    ca, *_ = import_build_deps()
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import maximum_bipartite_matching

    where = f"{model.source}: model {model.name}"
    n_eq, n_unk = len(residuals), len(unknowns)
    if n_eq != n_unk:
        raise BuildError(
            f"{where}: the model is not balanced: {n_eq} equations for {n_unk} unknowns "
            f"({', '.join(unknown_names)})"
        )
    if n_eq == 0:
        raise BuildError(f"{where}: the model has no equations")
    rows, cols = [], []
    for i, r in enumerate(residuals):
        for j, z in enumerate(unknowns):
            if ca.depends_on(r, z):
                rows.append(i)
                cols.append(j)
    inc = csr_matrix(([1] * len(rows), (rows, cols)), shape=(n_eq, n_unk))
    match = maximum_bipartite_matching(inc, perm_type="column")  # eq i -> unknown match[i]
    if (match < 0).any():
        bad = [model.equation_label(i) for i in range(n_eq) if match[i] < 0]
        raise BuildError(
            f"{where}: the equations are structurally singular; no unknown left to solve "
            f"equation(s): {'; '.join(bad)}"
        )
    eq_of_unknown = {int(match[i]): i for i in range(n_eq)}
    succ = [
        sorted({eq_of_unknown[j] for j in inc.indices[inc.indptr[i] : inc.indptr[i + 1]]} - {i})
        for i in range(n_eq)
    ]
    return _tarjan(n_eq, succ), match


def _solve_blocks(
    model: FlatModel,
    residuals: list[Any],
    unknowns: list[Any],
    unknown_names: list[str],
) -> tuple[list[Any], list[Any], list[tuple[list[int], Any, Any]]]:
    """Solve the blocks in order: explicit values, and the blocks left for Newton."""
    ca, *_ = import_build_deps()
    where = f"{model.source}: model {model.name}"
    blocks, match = _blocks(model, residuals, unknowns, unknown_names)
    known_syms: list[Any] = []
    known_vals: list[Any] = []
    implicit: list[tuple[list[int], Any, Any]] = []
    for block in blocks:
        idx = [int(match[i]) for i in block]
        res = [residuals[i] for i in block]
        if known_syms:
            res = ca.substitute(res, known_syms, known_vals)
        zs = [unknowns[j] for j in idx]
        if len(block) == 1:
            r, z = res[0], zs[0]
            jac = ca.jacobian(r, z)
            if not ca.depends_on(jac, z):
                if jac.is_zero():
                    raise BuildError(
                        f"{where}: equation {model.equation_label(block[0])} does not "
                        f"determine {unknown_names[idx[0]]}"
                    )
                sol = ca.simplify(-ca.substitute(r, z, ca.SX(0.0)) / jac)
                known_syms.append(z)
                known_vals.append(sol)
                continue
        implicit.append((idx, ca.vertcat(*res), ca.vertcat(*zs)))
        # Unknowns of an implicit block stay symbolic here; they are resolved later.
        known_syms.extend(zs)
        known_vals.extend(zs)
    return known_syms, known_vals, implicit


def causalize(model: FlatModel, *, frozen: bool = False) -> Causalized:
    """Sort and solve the equations of a flattened model for derivatives and algebraics.

    Parameters
    ----------
    model : FlatModel
        The model from :func:`~.modelica.flatten_model`.
    frozen : bool, optional
        Build the Model Exchange form, in which the model's relations are discrete states
        (an extra argument ``c``), with their event indicators. Default: the live form.

    Returns
    -------
    Causalized
        The explicit functions and the variable layout.

    Raises
    ------
    BuildError
        If the model is not balanced or structurally singular.
    """
    ca, *_ = import_build_deps()
    residuals = model.residuals_frozen if frozen else model.residuals
    algebraic = model.outputs + model.locals
    unknowns = list(model.der_syms) + [v.sym for v in algebraic]
    unknown_names = [f"der({v.name})" for v in model.states] + [v.name for v in algebraic]
    known_syms, known_vals, implicit = _solve_blocks(model, residuals, unknowns, unknown_names)

    def column(vs: list[Any]) -> Any:
        return ca.vertcat(*vs) if vs else ca.SX(0, 1)

    args = [
        model.time,
        column([v.sym for v in model.states]),
        column([v.sym for v in model.inputs]),
        column([v.sym for v in model.parameters]),
    ]
    names = ["t", "x", "u", "p"]
    relations = model.relations if frozen else []
    indicators: list[Any] = []
    if frozen:
        args.append(column([r.sym for r in relations]))
        names.append("c")
        exprs = [r.hi - r.lo for r in relations] + [
            ca.fabs(r.hi) + ca.fabs(r.lo) for r in relations
        ]
        indicators = ca.substitute(exprs, known_syms, known_vals) if exprs else []
    if implicit:
        out = _causalize_implicit(
            model, unknowns, known_syms, known_vals, implicit, args, names, indicators
        )
    else:
        out = _causalize_explicit(model, unknowns, known_syms, known_vals, args, names, frozen)
        if indicators:
            n = len(relations)
            out.rel = ca.Function(
                "rel", args, [column(indicators[:n]), column(indicators[n:])], names, ["z", "s"]
            )
    out.relations = list(relations)
    return out


def _layout(model: FlatModel) -> Layout:
    return Layout(model.states, model.inputs, model.outputs, model.parameters, model.locals)


def _causalize_explicit(
    model: FlatModel,
    unknowns: list[Any],
    known_syms: list[Any],
    known_vals: list[Any],
    args: list[Any],
    names: list[str],
    frozen: bool,
) -> Causalized:
    """Build the SX functions when every block was solved symbolically."""
    ca, *_ = import_build_deps()
    nx = len(model.states)
    sol = dict(zip([id(z) for z in known_syms], known_vals, strict=True))
    vals = [sol[id(z)] for z in unknowns]
    dx = ca.vertcat(*vals[:nx]) if nx else ca.SX(0, 1)
    w = ca.vertcat(*vals[nx:]) if len(vals) > nx else ca.SX(0, 1)
    f_ode = ca.Function("ode", args, [dx], names, ["dx"])
    f_eval = ca.Function("eval", args, [dx, w], names, ["dx", "w"])
    f_zc = None
    if not frozen:
        scalars = [dx[i] for i in range(dx.numel())] + [w[i] for i in range(w.numel())]
        rel = _relations(ca, scalars)
        f_zc = ca.Function("zc", args, [ca.vertcat(*rel)], names, ["z"]) if rel else None
    return Causalized(f_ode, f_eval, _layout(model), 0, f_zc)


def _block_order(
    unknowns: list[Any], known_syms: list[Any], implicit: list[tuple[list[int], Any, Any]]
) -> list[tuple[str, Any]]:
    """Reconstruct the block order: implicit blocks appear as runs of their unknowns."""
    implicit_ids = {id(z) for idx, _, _ in implicit for z in (unknowns[j] for j in idx)}
    order: list[tuple[str, Any]] = []
    seen: set[int] = set()
    for z in known_syms:
        if id(z) in seen:
            continue
        if id(z) in implicit_ids:
            blk = next(b for b in implicit if any(unknowns[j] is z for j in b[0]))
            order.append(("implicit", blk))
            seen.update(id(unknowns[j]) for j in blk[0])
        else:
            order.append(("explicit", z))
            seen.add(id(z))
    return order


def _causalize_implicit(
    model: FlatModel,
    unknowns: list[Any],
    known_syms: list[Any],
    known_vals: list[Any],
    implicit: list[tuple[list[int], Any, Any]],
    args: list[Any],
    names: list[str],
    indicators: list[Any],
) -> Causalized:
    """Build the functions in MX when some blocks need a Newton solve at run time."""
    ca, *_ = import_build_deps()
    where = f"{model.source}: model {model.name}"
    start = {}
    for v in model.outputs + model.locals:
        start[id(v.sym)] = v.start if v.start is not None else 0.0
    # MX inputs mirroring the SX ones.
    mx_args = [ca.MX.sym(n, a.numel()) for n, a in zip(names, args, strict=True)]
    flat_in = ca.vertcat(*args)
    flat_mx = ca.vertcat(*mx_args)
    value: dict[int, Any] = {}  # id(SX unknown) -> MX value

    def mx_of(expr: Any) -> Any:
        """Evaluate an SX expression of (t, x, u, p[, c], solved unknowns) in MX."""
        deps = [z for z in unknowns if id(z) in value and ca.depends_on(expr, z)]
        f = ca.Function("f", [flat_in, *deps], [expr])
        return f(flat_mx, *[value[id(z)] for z in deps])

    pending = dict(zip([id(z) for z in known_syms], known_vals, strict=True))
    for n_blk, (kind, item) in enumerate(_block_order(unknowns, known_syms, implicit)):
        if kind == "explicit":
            value[id(item)] = mx_of(pending[id(item)])
            continue
        idx, res, zs = item
        deps = [z for z in unknowns if id(z) in value and ca.depends_on(res, z)]
        pvec = ca.vertcat(flat_in, *deps)
        g = ca.Function(f"g{n_blk}", [zs, pvec], [res])
        try:
            rf = ca.rootfinder(
                f"newton{n_blk}",
                "fast_newton",
                g,
                {"abstol": 1e-12, "max_iter": 50, "error_on_fail": False},
            )
        except RuntimeError as exc:
            raise BuildError(
                f"{where}: cannot set up the Newton solve of block {n_blk}: {exc}"
            ) from exc
        guess = ca.DM([start.get(id(z), 0.0) for z in (unknowns[j] for j in idx)])
        pval = ca.vertcat(flat_mx, *[value[id(z)] for z in deps])
        sol = rf(guess, pval)
        for k, j in enumerate(idx):
            value[id(unknowns[j])] = sol[k]
    nx = len(model.states)
    vals = [value[id(z)] for z in unknowns]
    dx = ca.vertcat(*vals[:nx]) if nx else ca.MX(0, 1)
    w = ca.vertcat(*vals[nx:]) if len(vals) > nx else ca.MX(0, 1)
    f_ode = ca.Function("ode", mx_args, [dx], names, ["dx"])
    f_eval = ca.Function("eval", mx_args, [dx, w], names, ["dx", "w"])
    out = Causalized(f_ode, f_eval, _layout(model), len(implicit))
    if indicators:
        n = len(indicators) // 2
        z = ca.vertcat(*[mx_of(e) for e in indicators[:n]])
        s = ca.vertcat(*[mx_of(e) for e in indicators[n:]])
        out.rel = ca.Function("rel", mx_args, [z, s], names, ["z", "s"])
    return out
