"""Causalize the flattened equations and generate the model part of the FMU in C.

The residuals ``r(der(x), w; t, x, u, p) = 0`` of a :class:`~.modelica.FlatModel` are
sorted into blocks (maximum matching and strongly connected components, i.e. a BLT
decomposition). A scalar block whose residual is affine in its unknown is solved
symbolically; any other block (an algebraic loop or a nonlinear equation) is solved at
run time by CasADi's ``fast_newton`` root finder, which CasADi can generate C code for.

The result is two CasADi functions, code-generated into ``model_casadi.c``:

``<id>_ode(t, x, u, p) -> der(x)``
    the right-hand side, used by the integrator;
``<id>_eval(t, x, u, p) -> (der(x), w)``
    derivatives plus all algebraic variables ``w = [outputs, locals]``.

``model.h`` describes the value-reference layout to the generic wrapper in
``tsid_fmu/build/c/fmi2Functions.c``, ``model.c`` holds the start values, names and the
two thin adapters that call the CasADi functions.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from tsid_fmu.errors import BuildError

from .modelica import FlatModel, Variable, import_build_deps

__all__ = ["Causalized", "Layout", "causalize", "generate_c"]


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
        ``(t, x, u, p) -> der(x)``.
    eval : casadi.Function
        ``(t, x, u, p) -> (der(x), w)`` with ``w = [outputs, locals]``.
    layout : Layout
        Variable layout.
    n_implicit : int
        Number of blocks solved by Newton iteration at run time.
    zc : casadi.Function or None
        ``(t, x, u, p) -> z``: event indicators, one per distinct relation ``a < b`` /
        ``a <= b`` in the explicit equations (``z = b - a``; the relation holds when
        ``z > 0``, resp. ``z >= 0``). ``None`` if there are none.
    """

    ode: Any
    eval: Any
    layout: Layout
    n_implicit: int
    zc: Any = None


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


def causalize(model: FlatModel) -> Causalized:
    """Sort and solve the equations of a flattened model for derivatives and algebraics.

    Parameters
    ----------
    model : FlatModel
        The model from :func:`~.modelica.flatten_model`.

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
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import maximum_bipartite_matching

    where = f"{model.source}: model {model.name}"
    algebraic = model.outputs + model.locals
    unknowns = list(model.der_syms) + [v.sym for v in algebraic]
    unknown_names = [f"der({v.name})" for v in model.states] + [v.name for v in algebraic]
    n_eq, n_unk = len(model.residuals), len(unknowns)
    if n_eq != n_unk:
        raise BuildError(
            f"{where}: the model is not balanced: {n_eq} equations for {n_unk} unknowns "
            f"({', '.join(unknown_names)})"
        )
    if n_eq == 0:
        raise BuildError(f"{where}: the model has no equations")

    rows, cols = [], []
    for i, r in enumerate(model.residuals):
        for j, z in enumerate(unknowns):
            if ca.depends_on(r, z):
                rows.append(i)
                cols.append(j)
    inc = csr_matrix(([1] * len(rows), (rows, cols)), shape=(n_eq, n_unk))
    match = maximum_bipartite_matching(inc, perm_type="column")  # eq i -> unknown match[i]
    if (match < 0).any():
        bad = [model.equation_text[i] for i in range(n_eq) if match[i] < 0]
        raise BuildError(
            f"{where}: the equations are structurally singular; no unknown left to solve "
            f"equation(s): {'; '.join(bad)}"
        )
    eq_of_unknown = {int(match[i]): i for i in range(n_eq)}
    succ = [
        sorted({eq_of_unknown[j] for j in inc.indices[inc.indptr[i] : inc.indptr[i + 1]]} - {i})
        for i in range(n_eq)
    ]
    blocks = _tarjan(n_eq, succ)

    t = model.time
    x = ca.vertcat(*[v.sym for v in model.states]) if model.states else ca.SX(0, 1)
    u = ca.vertcat(*[v.sym for v in model.inputs]) if model.inputs else ca.SX(0, 1)
    p = ca.vertcat(*[v.sym for v in model.parameters]) if model.parameters else ca.SX(0, 1)
    known_syms: list[Any] = []
    known_vals: list[Any] = []
    implicit: list[tuple[list[int], Any, Any]] = []
    for block in blocks:
        idx = [int(match[i]) for i in block]
        res = [model.residuals[i] for i in block]
        if known_syms:
            res = ca.substitute(res, known_syms, known_vals)
        zs = [unknowns[j] for j in idx]
        if len(block) == 1:
            r, z = res[0], zs[0]
            jac = ca.jacobian(r, z)
            if not ca.depends_on(jac, z):
                if jac.is_zero():
                    raise BuildError(
                        f"{where}: equation '{model.equation_text[block[0]]}' does not "
                        f"determine {unknown_names[idx[0]]}"
                    )
                sol = ca.simplify(-ca.substitute(r, z, ca.SX(0.0)) / jac)
                known_syms.append(z)
                known_vals.append(sol)
                continue
        implicit.append((idx, ca.vertcat(*res), ca.vertcat(*zs)))
        # Unknowns of an implicit block stay symbolic here; they are resolved below.
        known_syms.extend(zs)
        known_vals.extend(zs)

    args = [t, x, u, p]
    names = ["t", "x", "u", "p"]
    nx = len(model.states)
    if not implicit:
        sol = dict(zip([id(z) for z in known_syms], known_vals, strict=True))
        vals = [sol[id(z)] for z in unknowns]
        dx = ca.vertcat(*vals[:nx]) if nx else ca.SX(0, 1)
        w = ca.vertcat(*vals[nx:]) if len(vals) > nx else ca.SX(0, 1)
        f_ode = ca.Function("ode", args, [dx], names, ["dx"])
        f_eval = ca.Function("eval", args, [dx, w], names, ["dx", "w"])
        scalars = [dx[i] for i in range(dx.numel())] + [w[i] for i in range(w.numel())]
        rel = _relations(ca, scalars)
        f_zc = ca.Function("zc", args, [ca.vertcat(*rel)], names, ["z"]) if rel else None
        return Causalized(
            f_ode,
            f_eval,
            Layout(model.states, model.inputs, model.outputs, model.parameters, model.locals),
            0,
            f_zc,
        )
    return _causalize_implicit(model, unknowns, known_syms, known_vals, implicit, args, names)


def _causalize_implicit(
    model: FlatModel,
    unknowns: list[Any],
    known_syms: list[Any],
    known_vals: list[Any],
    implicit: list[tuple[list[int], Any, Any]],
    args: list[Any],
    names: list[str],
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
        """Evaluate an SX expression of (t, x, u, p, solved unknowns) in MX."""
        deps = [z for z in unknowns if id(z) in value and ca.depends_on(expr, z)]
        f = ca.Function("f", [flat_in, *deps], [expr])
        return f(flat_mx, *[value[id(z)] for z in deps])

    pending = dict(zip([id(z) for z in known_syms], known_vals, strict=True))
    implicit_ids = {id(z) for idx, _, _ in implicit for z in (unknowns[j] for j in idx)}
    order = []
    # Reconstruct the block order: known_syms is in solve order; implicit blocks
    # appear as runs of their own unknowns.
    seen = set()
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
    for n_blk, (kind, item) in enumerate(order):
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
    layout = Layout(model.states, model.inputs, model.outputs, model.parameters, model.locals)
    return Causalized(f_ode, f_eval, layout, len(implicit))


def _zc_adapter(zc: Any, ident: str) -> str:
    if zc is None:
        return """
int model_zc(double t, const double *x, const double *u, const double *p, double *z) {
    (void)t;
    (void)x;
    (void)u;
    (void)p;
    (void)z;
    return 0;
}
"""
    return f"""
int model_zc(double t, const double *x, const double *u, const double *p, double *z) {{
    const double *arg[{max(zc.sz_arg(), 1)}];
    double *res[{max(zc.sz_res(), 1)}];
    long long int iw[{max(zc.sz_iw(), 1)}];
    double w[{max(zc.sz_w(), 1)}];
    arg[0] = &t;
    arg[1] = x;
    arg[2] = u;
    arg[3] = p;
    res[0] = z;
    return {ident}_zc(arg, res, iw, w, 0);
}}
"""


def _c_double(v: float | None) -> str:
    if v is None:
        return "0.0"
    return repr(float(v))


def _c_string(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"').replace("\n", " ") + '"'


def generate_c(
    model: FlatModel,
    causal: Causalized,
    outdir: str | Path,
    *,
    guid: str,
    step_size: float,
) -> list[str]:
    """Write the generated model part (``model.h``, ``model.c``, ``model_casadi.c/h``).

    Parameters
    ----------
    model : FlatModel
        The flattened model.
    causal : Causalized
        Its explicit form from :func:`causalize`.
    outdir : str or Path
        Directory to write into (the FMU's ``sources/``).
    guid : str
        The FMU's GUID, compiled in and checked by ``fmi2Instantiate``.
    step_size : float
        Default of the Co-Simulation parameter ``fixedStepSize``.

    Returns
    -------
    list of str
        The generated ``.c`` file names.
    """
    ca, *_ = import_build_deps()
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    ident = model.short_name
    lay = causal.layout
    fun_ode = f"{ident}_ode"
    fun_eval = f"{ident}_eval"
    ode, ev = causal.ode, causal.eval
    if causal.n_implicit == 0:
        ode, ev = ode.expand(), ev.expand()
    ode = ca.Function(
        fun_ode,
        ode.mx_in() if ode.is_a("MXFunction") else ode.sx_in(),
        ode.call(ode.mx_in() if ode.is_a("MXFunction") else ode.sx_in()),
        ode.name_in(),
        ode.name_out(),
    )
    ev = ca.Function(
        fun_eval,
        ev.mx_in() if ev.is_a("MXFunction") else ev.sx_in(),
        ev.call(ev.mx_in() if ev.is_a("MXFunction") else ev.sx_in()),
        ev.name_in(),
        ev.name_out(),
    )
    cg = ca.CodeGenerator(
        "model_casadi.c",
        {
            "with_header": True,
            "with_export": False,
            "casadi_real": "double",
            "casadi_int": "long long int",
            "verbose": False,
        },
    )
    cg.add(ode)
    cg.add(ev)
    nz = 0
    zc = None
    if causal.zc is not None:
        zc = ca.Function(
            f"{ident}_zc",
            causal.zc.sx_in(),
            causal.zc.call(causal.zc.sx_in()),
            causal.zc.name_in(),
            causal.zc.name_out(),
        )
        nz = zc.numel_out(0)
        cg.add(zc)
    cg.generate(str(outdir) + "/")

    n_alg = len(lay.outputs) + len(lay.locals)
    all_vars = (
        [(v.name, v.start) for v in lay.states]
        + [(f"der({v.name})", None) for v in lay.states]
        + [(v.name, v.start) for v in lay.inputs]
        + [(v.name, v.start) for v in lay.outputs + lay.locals]
        + [(v.name, v.start) for v in lay.parameters]
        + [("fixedStepSize", step_size)]
    )
    assert len(all_vars) == lay.n_real
    h = f"""/* Generated by tsid-fmu from {model.source.name}, model {model.name}. Do not edit.
 * The value reference of a real variable is its index in the instance's real array. */
#ifndef TSID_MODEL_H
#define TSID_MODEL_H

#define MODEL_IDENTIFIER {ident}
#define MODEL_NAME "{model.name}"
#define INSTANTIATION_TOKEN "{guid}"

#define NX {lay.nx}
#define NU {len(lay.inputs)}
#define NY {len(lay.outputs)}
#define NW {n_alg}
#define NP {len(lay.parameters)}
#define NZ {nz}
#define X_OFF {lay.x_off}
#define DX_OFF {lay.dx_off}
#define U_OFF {lay.u_off}
#define W_OFF {lay.y_off}
#define P_OFF {lay.p_off}
#define VR_FIXED_STEP {lay.h_vr}
#define N_REAL {lay.n_real}

/* Start values (index = value reference) and names, for reset and log messages. */
extern const double model_start[N_REAL];
extern const char *const model_names[N_REAL];

/* Right-hand side: dx = f(t, x, u, p). Returns 0 on success. */
int model_ode(double t, const double *x, const double *u, const double *p, double *dx);
/* Derivatives and algebraic variables w = [outputs, locals]. Returns 0 on success. */
int model_eval(double t, const double *x, const double *u, const double *p,
               double *dx, double *w);
/* Event indicators z (NZ of them): one per relation a < b / a <= b, z = b - a. */
int model_zc(double t, const double *x, const double *u, const double *p, double *z);

#endif
"""
    (outdir / "model.h").write_text(h)

    def work(f: Any) -> tuple[int, int, int, int]:
        sz_arg, sz_res, sz_iw, sz_w = f.sz_arg(), f.sz_res(), f.sz_iw(), f.sz_w()
        return max(sz_arg, 1), max(sz_res, 1), max(sz_iw, 1), max(sz_w, 1)

    a1, r1, i1, w1 = work(ode)
    a2, r2, i2, w2 = work(ev)
    starts = ",\n    ".join(_c_double(s) for _, s in all_vars)
    names = ",\n    ".join(_c_string(n) for n, _ in all_vars)
    c = f"""/* Generated by tsid-fmu from {model.source.name}, model {model.name}. Do not edit.
 * Thin adapters between the generic FMI wrapper and the CasADi-generated equations. */
#include "model.h"
#include "model_casadi.h"

const double model_start[N_REAL] = {{
    {starts}
}};

const char *const model_names[N_REAL] = {{
    {names}
}};

int model_ode(double t, const double *x, const double *u, const double *p, double *dx) {{
    const double *arg[{a1}];
    double *res[{r1}];
    long long int iw[{i1}];
    double w[{w1}];
    arg[0] = &t;
    arg[1] = x;
    arg[2] = u;
    arg[3] = p;
    res[0] = dx;
    return {fun_ode}(arg, res, iw, w, 0);
}}

int model_eval(double t, const double *x, const double *u, const double *p,
               double *dx, double *wout) {{
    const double *arg[{a2}];
    double *res[{r2}];
    long long int iw[{i2}];
    double w[{w2}];
    arg[0] = &t;
    arg[1] = x;
    arg[2] = u;
    arg[3] = p;
    res[0] = dx;
    res[1] = wout;
    return {fun_eval}(arg, res, iw, w, 0);
}}
""" + _zc_adapter(zc, ident)
    (outdir / "model.c").write_text(c)
    return ["model.c", "model_casadi.c"]
