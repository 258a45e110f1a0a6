"""Name what the data fix across a subspace no input separates.

One structural direction (the capacity against the two resistances of a thermal model)
leaves products the data fix: :func:`tsid_fmu.uncertainty.probe.fixed_across` names
them pairwise (``C R1``, ``C R2``). Several directions at once (three position offsets
of which the output sees only a sum) leave fewer combinations than members, and no
pairing names them: each combination across the subspace is written out with one pivot
member per combination (reduced row-echelon form, so the list does not depend on the
directions' arbitrary rotation), in the form in which its coefficients are simplest: a
product of powers (``x1 x2^-1``) or a weighted sum (``x1 + 0.5 x2``), whichever lies
closer to whole and half coefficients. Its value and 95 % interval come from the
covariance within the determined directions.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from tsid_fmu.search.space import Space
from tsid_fmu.uncertainty.intervals import Z95, Uncertainty
from tsid_fmu.uncertainty.probe import MEMBER, fixed_across

__all__ = ["combinations_across"]


def _rref(a: np.ndarray) -> np.ndarray:
    """Return the reduced row-echelon form of ``a`` (rows: combinations), partial pivoting."""
    a = a.astype(float).copy()
    row = 0
    for col in range(a.shape[1]):
        if row == a.shape[0]:
            break
        pivot = row + int(np.argmax(np.abs(a[row:, col])))
        if abs(a[pivot, col]) < 1e-9:
            continue
        a[[row, pivot]] = a[[pivot, row]]
        a[row] /= a[row, col]
        for other in range(a.shape[0]):
            if other != row:
                a[other] -= a[other, col] * a[row]
        row += 1
    return a[:row]


def _roughness(coefficients: np.ndarray) -> float:
    """How far coefficients lie from whole and half numbers (0: all of them on one)."""
    return float(np.sum(np.abs(2 * coefficients - np.round(2 * coefficients))))


SIMPLE = 0.02
"""How near a whole or half number a coefficient may lie to be written as one."""
TOUCH = 0.05
"""A parameter whose share of a subspace of several directions reaches this is in it:
the share from which a direction names a parameter (:func:`~tsid_fmu.uncertainty.
intervals.combination_terms`)."""
POWERS = (-2, -1, 0, 1, 2)
"""The exponents a named monomial may have (``J L Kt^-1``)."""
MONOMIAL_MEMBERS = 6
"""Members of a subspace up to which every monomial of :data:`POWERS` is tried (5^6)."""


def _simple(a: float) -> float:
    """Return ``a`` rounded to a whole or half number where it lies within :data:`SIMPLE`."""
    k = round(2 * a) / 2
    return k if k != 0 and abs(a - k) < SIMPLE * max(abs(a), 1.0) else a


def _monomials(
    space: Space, idx: list[int], basis: np.ndarray, cov: np.ndarray, reach: float, most: int
) -> list[np.ndarray]:
    """Return up to ``most`` independent monomials of the members that the subspace fixes.

    A product of the members' powers (:data:`POWERS`) has the direction ``c`` in the
    search coordinates (``e_j`` times the width of ``lg x_j``). The subspace fixes it
    when ``reach`` along the subspace (one first range) changes it by less than the data
    determine it: ``reach |basis^T c| <= sqrt(c^T cov c)``. Where one exists it is a
    global invariant and the simplest name (a DC motor measured by its speed: ``J L
    Kt^-1``, its transfer function's leading coefficient, lies across the subspace to
    2e-5 of its length, its standard error 5e-4; the nearest others to 0.002 to 0.015, on
    ten noise seeds, with standard errors of 0.001: a quarter range, the distance the
    design follows a direction, let two of them through). The simplest are taken first
    (fewest members, then smallest powers). Returned as exponent vectors over ``idx``;
    none unless every member is a log coordinate.
    """
    if not all(space.log[j] for j in idx) or len(idx) > MONOMIAL_MEMBERS or most <= 0:
        return []
    finite = np.where(np.isfinite(cov), cov, 0.0)[np.ix_(idx, idx)]
    width, near = space.width[idx], basis[idx]
    grid = np.array(np.meshgrid(*[POWERS] * len(idx), indexing="ij")).reshape(len(idx), -1).T
    grid = grid[np.any(grid != 0, axis=1)]
    order = np.count_nonzero(grid, axis=1) * 100 + np.abs(grid).sum(axis=1)
    found: list[np.ndarray] = []
    for e in grid[np.argsort(order, kind="stable")]:
        if e[np.flatnonzero(e)[0]] < 0:  # one sign of each: x y^-1, not x^-1 y
            continue
        c = e * width
        if reach * np.linalg.norm(near.T @ c) > np.sqrt(max(float(c @ finite @ c), 0.0)):
            continue
        if np.linalg.matrix_rank(np.array([*found, e])) > len(found):
            found.append(e.astype(float))
            if len(found) == most:
                break
    return found


def _fixes(near: np.ndarray, c: np.ndarray, finite: np.ndarray, reach: float) -> np.ndarray:
    """Whether each row of ``c`` (directions) stays fixed ``reach`` along the subspace."""
    moved = reach * np.linalg.norm(c @ near, axis=1)
    sigma = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", c, finite, c), 0.0))
    return moved <= sigma


def _binomials(
    space: Space,
    idx: list[int],
    basis: np.ndarray,
    cov: np.ndarray,
    reach: float,
    taken: list[np.ndarray],
    most: int,
    base: np.ndarray,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Return up to ``most`` sums of two monomials that the subspace fixes.

    A transfer function's coefficients are often sums of products (``(J R + b L) /
    Kt``): the sum ``m1 + m2`` of two monomials with powers in -1, 0, 1 has the
    direction ``(m1 e1 + m2 e2)`` times the widths, tested as :func:`_monomials` tests
    one, and independent of ``taken`` (directions already named). Pairs of fewer members
    and smaller powers first. Returned as ``(e1, e2)`` exponent pairs over ``idx``.
    """
    if most <= 0 or len(idx) > MONOMIAL_MEMBERS:
        return []
    width = space.width[idx]
    grid = np.array(np.meshgrid(*[(-1, 0, 1)] * len(idx), indexing="ij")).reshape(len(idx), -1).T
    grid = grid[np.any(grid != 0, axis=1)].astype(float)
    m = np.prod(base[None, :] ** grid, axis=1)
    i, j = np.triu_indices(len(grid), k=1)
    c = (m[i, None] * grid[i] + m[j, None] * grid[j]) * width[None, :]
    finite = np.where(np.isfinite(cov), cov, 0.0)[np.ix_(idx, idx)]
    ok = _fixes(basis[idx], c, finite, reach)
    order = np.count_nonzero(grid[i], axis=1) + np.count_nonzero(grid[j], axis=1)
    order = order * 100 + np.abs(grid[i]).sum(axis=1) + np.abs(grid[j]).sum(axis=1)
    found: list[tuple[np.ndarray, np.ndarray]] = []
    rows = [t / np.linalg.norm(t) for t in taken]
    for k in np.flatnonzero(ok)[np.argsort(order[ok], kind="stable")]:
        direction = c[k] / np.linalg.norm(c[k])
        stacked = np.array([*rows, direction])
        if np.linalg.svd(stacked, compute_uv=False).min() > SIMPLE:  # independent
            rows.append(direction)
            found.append((grid[i[k]], grid[j[k]]))
            if len(found) == most:
                break
    return found


def _product(names: list[str], coef: np.ndarray) -> tuple[str, Any]:
    """Name and value function of the product of ``names`` to the powers ``coef``."""
    name = " ".join(
        f"{n}" + ("" if c == 1 else f"^{c:g}") for n, c in zip(names, coef, strict=True) if c
    )
    return name, (lambda v: float(np.prod(v**coef)))


def _named(
    space: Space, idx: list[int], g: np.ndarray, x: dict
) -> tuple[str, Any, np.ndarray, str]:
    """Return the name, value function, coefficients and form of combination ``g``.

    The form is ``"product"`` (coefficients: powers) or ``"sum"`` (weights).
    """
    names = [space.names[j] for j in idx]
    values = np.array([x[n] for n in names], dtype=float)
    log = all(space.log[j] for j in idx)
    forms = []
    if log and np.all(values > 0):  # g on lg x: a product; locally a sum with g / x
        forms.append(("product", g / g[np.argmax(np.abs(g))]))
        linear = g / values
        forms.append(("sum", linear / linear[np.argmax(np.abs(linear))]))
    elif not any(space.log[j] for j in idx):
        forms.append(("sum", g / g[np.argmax(np.abs(g))]))
    if not forms:
        return "", None, g, ""
    kind, coef = min(forms, key=lambda f: _roughness(f[1]))
    coef = np.array([_simple(float(c)) for c in coef])
    if kind == "product":
        name, value = _product(names, coef)
        return name, value, coef, kind
    name = " ".join(
        f"{'+' if c > 0 else '-'} {'' if abs(c) == 1 else f'{abs(c):g} '}{n}"
        for n, c in zip(names, coef, strict=True)
        if c
    ).lstrip("+ ")
    return name, (lambda v: float(np.dot(coef, v))), coef, kind


def _interval(space: Space, idx: list[int], value: Any, x: dict, cov: np.ndarray) -> list:
    """Return a 95 % interval of ``value`` from ``cov`` (search coordinates), by gradient."""
    s0 = space.to_s(x)
    base = np.array([x[space.names[j]] for j in idx], dtype=float)
    centre = value(base)
    grad = np.zeros(space.dim)
    for j in idx:
        s = s0.copy()
        s[j] += 1e-6
        moved = space.to_x(s)
        grad[j] = (value(np.array([moved[space.names[i]] for i in idx])) - centre) / 1e-6
    finite = np.where(np.isfinite(cov), cov, 0.0)
    half = Z95 * math.sqrt(max(float(grad @ finite @ grad), 0.0))
    return [centre - half, centre + half]


def combinations_across(
    space: Space, x: dict, basis: np.ndarray, cov: np.ndarray, reach: float = 1.0
) -> tuple[list[str], list[dict[str, Any]]]:
    """Return the members of a structural subspace and the combinations the data fix.

    ``basis`` holds the subspace's orthonormal directions as columns (search
    coordinates); ``cov`` is the covariance of the determined directions; ``reach`` how
    far along the subspace a monomial must stay fixed (search units). One direction: the
    pairwise products of its members (a share of :data:`MEMBER` or more). Several: every
    parameter the subspace touches (:data:`TOUCH`) is a member, since a combination that
    leaves one out is no invariant (the motor's ``Kt``, at a share of 0.2, left out on
    two noise seeds of ten, gave combinations of R, L, J, b that excluded the truth); the
    simplest monomials the subspace fixes first (:func:`_monomials`), then the rest in
    reduced row-echelon form.
    """
    weight = np.sqrt((basis**2).sum(axis=1))
    share = MEMBER if basis.shape[1] == 1 else TOUCH
    idx = [j for j in range(space.dim) if weight[j] >= share]
    members = [space.names[j] for j in idx]
    if basis.shape[1] == 1:  # one direction: the pairwise products, as the study names them
        u = Uncertainty(values=dict(x))
        u.cov = cov
        u.dof = {n: 1e6 for n in space.names}
        return members, fixed_across(space, u, basis[:, 0], members)
    inside = np.eye(space.dim)[:, idx]
    across = inside - basis @ (basis.T @ inside)
    u, s, _ = np.linalg.svd(across, full_matrices=False)
    keep = u[:, s > 0.5]  # a member's axis is a unit vector: what lies across has norm ~1
    names = [space.names[j] for j in idx]
    base = np.array([x[n] for n in names], dtype=float)
    out = []
    most = keep.shape[1] if np.all(base > 0) else 0
    monomials = _monomials(space, idx, basis, cov, reach, most)
    for e in monomials:
        name, value = _product(names, e)
        out.append({"name": name, "value": value(base),
                    "interval": _interval(space, idx, value, x, cov), "form": "product",
                    "coefficients": _coefficients(names, e)})  # fmt: skip
    named = [e * space.width[idx] for e in monomials]
    pairs = _binomials(space, idx, basis, cov, reach, named, most - len(monomials), base)
    for e1, e2 in pairs:
        (n1, v1), (n2, v2) = _product(names, e1), _product(names, e2)
        total = lambda v, a=v1, b=v2: a(v) + b(v)  # noqa: E731
        powers = [_coefficients(names, e1), _coefficients(names, e2)]
        out.append({"name": f"{n1} + {n2}", "value": total(base),
                    "interval": _interval(space, idx, total, x, cov),
                    "form": "sum of products", "coefficients": powers})  # fmt: skip
        m1, m2 = float(np.prod(base**e1)), float(np.prod(base**e2))
        named.append((m1 * e1 + m2 * e2) * space.width[idx])
    if named:  # the rest: what lies across the named ones too
        taken = np.zeros((space.dim, len(named)))
        taken[idx] = np.array(named).T
        q = np.linalg.qr(taken)[0]
        rest = keep - q @ (q.T @ keep)
        u, s, _ = np.linalg.svd(rest, full_matrices=False)
        keep = u[:, s > 0.5] if rest.size else rest
    rows = _rref((keep.T)[:, idx]) if keep.size else np.zeros((0, len(idx)))
    for r in rows:
        g = r / space.width[idx]  # coefficients on the working values (lg x or x)
        name, value, coef, form = _named(space, idx, g, x)
        if not name:
            continue
        out.append({"name": name, "value": value(base),
                    "interval": _interval(space, idx, value, x, cov), "form": form,
                    "coefficients": _coefficients(names, coef)})  # fmt: skip
    return members, out


def _coefficients(names: list[str], coef: np.ndarray) -> dict[str, float]:
    """Return the powers (a product) or weights (a sum) of a combination, by parameter."""
    return {n: float(c) for n, c in zip(names, coef, strict=True) if c}
