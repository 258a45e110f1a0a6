"""Test the loose combinations the covariance calls determined, by profiling along them.

A Fisher matrix computed by finite differences sees a little sensitivity even along an
exact symmetry (the integrator's and the differences' own noise), so a direction the
outputs do not depend on at all can come out with a finite standard error: OpenModelica's
``MassSpringSubSystem1`` (masses and stiffnesses scaled together) was reported with
finite intervals that excluded the truth, its scale called "determined" (issue 45).

So each combination that the covariance determines only loosely (a relative standard
error of :data:`LOOSE` % or more) is profiled at two points, one each side of the
answer, :data:`SPAN` of its 95 % half-widths away: the point along its direction, then
re-fitted across it by Gauss-Newton steps with the answer's Jacobian until a step gains
less than :data:`GAIN` of the 95 % threshold, at most :data:`REFITS` simulations (the
direction the differences give is tilted off an exact null direction, across it the
cost is steep, and where the symmetry is curved in the search coordinates, as a common
scale beside an offset that must follow it, the re-fit takes several steps). Were the
profile quadratic, as the covariance says, it would rise by ``SPAN**2`` times the 95 %
threshold; if it rises by less than :data:`FLAT` of that threshold on both sides, the
covariance saw noise, not the data: the combination is marked not determined. The
parameters in every combination not determined (so found, or by the covariance) get
open intervals, and a warning names it. At most ``2 * REFITS + 1`` simulations per
loose combination; none where every combination is well determined.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np

from tsid_fmu.errors import TsidError
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.evaluate.serial import SerialEvaluator
from tsid_fmu.numerics.space import Space
from tsid_fmu.numerics.tuning import CHORD_COSINE, FLAT, GAIN, LOOSE, MEMBER, NEAR, REFITS, SPAN
from tsid_fmu.uncertainty.intervals import (
    Uncertainty,
    combination_terms,
    quantile,
    seen_inverse,
)

__all__ = [
    "FLAT",
    "GAIN",
    "LOOSE",
    "REFITS",
    "SPAN",
    "fixed_across",
    "open_undetermined",
    "probe_combinations",
    "structural",
]


def _loose(c: Mapping) -> bool:
    se, percent = c.get("std_error", math.inf), c.get("percent", math.nan)
    return (
        bool(c.get("determined"))
        and math.isfinite(se)
        and "direction" in c
        and math.isfinite(percent)
        and percent >= LOOSE
    )


def _level(evaluator: Evaluator, space: Space, s0: np.ndarray, v: np.ndarray, cost: float) -> float:
    """Return the cost's level near the answer: the larger of ``cost`` and the cost nearby.

    An answer is the lowest of many evaluations, and where the FMU's own solver is
    noisy it is a lucky one: on JModelica's ``Simple2R1C`` every point along the exact
    symmetry cost 1.8 more than the answer (half the 95 % threshold), which read as a
    rise. The cost :data:`NEAR` along ``v``, so near that a curvature would rise there
    by a ten-thousandth of the probes' rise, is the level the probes are compared with.
    One simulation.
    """
    point = space.to_x(np.clip(s0 + NEAR * v, space.s_lower, space.s_upper))
    near = float(evaluator.evaluate([point]).costs[0, 0])
    return max(cost, near) if math.isfinite(near) else cost


def _profile(
    evaluator: Evaluator,
    space: Space,
    s: np.ndarray,
    across: np.ndarray,
    jac: np.ndarray,
    rise: float,
) -> tuple[float, dict[str, float] | None]:
    """Return the lowest cost found from ``s`` re-fitted along ``across``, and its point.

    The re-fit stops once a step gains less than :data:`GAIN` of ``rise`` (the 95 %
    threshold), or after :data:`REFITS` simulations.
    """
    step = seen_inverse(jac @ across)
    z, best, where = np.zeros(across.shape[1]), math.inf, None
    for _ in range(REFITS):
        point = space.to_x(np.clip(s + across @ z, space.s_lower, space.s_upper))
        ev = evaluator.evaluate([point])
        cost, r = float(ev.costs[0, 0]), ev.residuals[0] if ev.residuals else None
        if not math.isfinite(cost):
            break
        gained = best - cost
        if cost < best:
            best, where = cost, point
        if r is None or gained < GAIN * rise:
            break
        z = z - step @ r
    return best, where


def structural(
    evaluator: Evaluator, x: Mapping[str, float], points: list[dict], level: float
) -> bool | None:
    """Whether points the data cannot tell from ``x`` give its outputs for other inputs too.

    The study's inputs reversed in time are another input of the same kind (range,
    steps, spectrum); where the outputs at ``points`` (along a direction found flat)
    still match those at ``x`` to :data:`FLAT` times ``level`` (the RMS of the answer's
    scaled residuals: the noise, in the cost's units), no input separates them:
    the model depends on these parameters through fewer combinations whatever the
    experiment (a structural symmetry). None where it cannot be tried: no spec, no
    inputs, or a simulation failed. Three simulations per point and experiment.
    """
    spec = getattr(evaluator, "spec", None)
    if spec is None or not points or any(e.inputs is None for e in spec.experiments):
        return None
    other = [
        dataclasses.replace(e, inputs=np.ascontiguousarray(e.inputs[::-1]), noisy_inputs=())
        for e in spec.experiments
    ]
    try:
        with SerialEvaluator(dataclasses.replace(spec, experiments=tuple(other))) as ev:
            runs = ev.simulate([dict(x), *points], count=False)
    except TsidError:
        return None
    base = runs[0]
    for run in runs[1:]:
        for e, a, b in zip(other, base, run, strict=True):
            if a.outputs is None or b.outputs is None:
                return None
            rms = np.sqrt(np.mean(((b.outputs - a.outputs) / e.scale) ** 2, axis=0))
            if not float(np.max(rms)) <= FLAT * level:
                return False
    return True


def _along(space: Space, c: dict, points: list[dict[str, float]], v: np.ndarray) -> None:
    """Take the direction of a flat combination ``c`` from its two re-fitted probes.

    The points lie on the valley, so the chord between them is its direction, where the
    finite differences' eigenvector ``v`` is tilted by the solver's noise: on
    ``Mass_Damper`` the common scale of mass and damping came out with weights 0.552
    and 0.538, and the combination fixed across it was named ``damper.d mass.m^-0.974``
    with an interval that excluded the true d / m.
    """
    chord = space.to_s(points[0]) - space.to_s(points[1])
    norm = float(np.linalg.norm(chord))
    if not norm > 0 or not np.all(np.isfinite(chord)):
        return
    chord = chord / norm * (1.0 if float(chord @ v) >= 0 else -1.0)
    if float(chord @ v) < CHORD_COSINE * float(np.linalg.norm(v)):
        return  # not a tilt: a probe held at a bound, or a re-fit that went elsewhere
    c["direction"] = [float(e) for e in chord]
    c["terms"] = combination_terms(space, chord)


def probe_combinations(
    evaluator: Evaluator,
    space: Space,
    u: Uncertainty,
    x: Mapping[str, float],
    cost: float,
    rise: float,
    jac: np.ndarray,
) -> list[str]:
    """Profile ``u``'s loose combinations at the answer ``x``; mark those that are flat.

    ``cost`` is the answer's, ``rise`` the increase that bounds a 95 % interval, ``jac``
    the answer's residual Jacobian in ``space``'s coordinates. Returns a warning per
    combination found not determined; ``u`` is changed in place (the combination, and
    its members' intervals and standard errors).
    """
    loose = [c for c in u.combinations if _loose(c)]
    if not loose or not math.isfinite(cost) or jac.shape[1] != space.dim:
        return open_undetermined(space, u)
    t = quantile(max(min(u.dof.values(), default=1.0), 1.0))
    s0 = space.to_s(dict(x))
    warnings = []
    for c in loose:
        v = np.asarray(c["direction"], dtype=float)
        v = v / np.linalg.norm(v)
        across = np.linalg.svd(np.eye(space.dim) - np.outer(v, v))[0][:, : space.dim - 1]
        step = SPAN * t * float(c["std_error"])
        found = [
            _profile(evaluator, space, s0 + sign * step * v, across, jac, rise) for sign in (1, -1)
        ]
        finite = [f for f, _ in found if math.isfinite(f)]
        if not finite or max(finite) - _level(evaluator, space, s0, v, cost) > FLAT * rise:
            continue
        c["determined"], c["std_error"], c["percent"] = False, math.inf, math.inf
        c["why"] = (
            f"profiled {step:.3g} search units along it, both ways, the cost rises by less "
            "than the noise"
        )
        points = [p for _, p in found if p is not None]
        if len(points) == 2:
            _along(space, c, points, v)
        level = math.sqrt(cost / max(jac.shape[0], 1))
        c["structural"] = structural(evaluator, x, points, level)
        if c["structural"]:
            c["why"] += (
                "; with the inputs reversed in time the outputs there are the same too: no "
                "input separates these parameters, only another measurement or a known value"
            )
    return warnings + open_undetermined(space, u)


def open_undetermined(space: Space, u: Uncertainty) -> list[str]:
    """Open the intervals of the parameters in each combination that is not determined.

    A parameter's interval cannot be finite along a direction the data leave open: the
    scale of masses and stiffnesses that only act through their ratios had finite
    intervals, excluding the truth, while the combination said "not determined". The
    combinations counted are those the profile found flat, and those whose finite
    standard error is too large to determine them.
    Returns one warning per combination that opened an interval.
    """
    warnings = []
    for c in u.combinations:
        if c.get("determined") is not False or "direction" not in c:
            continue
        if not (c.get("why") or math.isfinite(c.get("std_error", math.inf))):
            # an infinite standard error: a direction the Fisher matrix does not see at
            # all, whose parameters' own variances are infinite already; a combination
            # only touching them (a determined m / c beside undetermined offsets) is not
            # a reason to open the others
            continue
        v = np.asarray(c["direction"], dtype=float)
        v = v / max(float(np.linalg.norm(v)), 1e-300)
        members = [n for j, n in enumerate(space.names) if abs(v[j]) >= MEMBER]
        opened = [n for n in members if u.intervals.get(n) != [None, None]]
        for name in members:
            u.intervals[name] = [None, None]
            u.std_error[name] = u.relative[name] = math.inf
        if opened:
            terms = " ".join(f"{k:+.2f} {name}" for name, k in c["terms"].items())
            why = c.get("why") or f"its standard error is {c['std_error']:.3g} search units"
            c["fixed"] = fixed_across(space, u, v, members)
            named = "; ".join(
                f"{f['name']} = {f['value']:.5g}"
                + (
                    f" ({f['interval'][0]:.5g} .. {f['interval'][1]:.5g})"
                    if f["interval"][0] is not None
                    else ""
                )
                for f in c["fixed"]
            )
            warnings.append(
                f"the data do not determine {terms} ({why}): {', '.join(members)} have open "
                "intervals; only the combinations across it are fixed"
                + (f": {named}" if named else "")
            )
    return warnings


def _exponent(a: float) -> str:
    """Write an exponent as a person would: 1 and -1 left out, near-integers as integers."""
    k = round(a)
    if abs(a - k) < 0.02 * max(abs(a), 1.0) and k != 0:
        return "" if k == 1 else "^-1" if k == -1 else f"^{k}"
    return f"^{a:.3g}"


def _rounded(a: float) -> float:
    """Return an exponent as :func:`_exponent` writes it: a near-integer as that integer.

    The value and the interval of a combination named ``C R1`` are those of ``C R1``,
    not of ``C R1^0.98`` (the direction the differences give is tilted off the exact
    symmetry by the solver's noise).
    """
    k = round(a)
    return float(k) if abs(a - k) < 0.02 * max(abs(a), 1.0) and k != 0 else a


def _pow10(exponent: float) -> float:
    """Return ``10 ** exponent``, infinite beyond a float's range (not OverflowError)."""
    return 10.0**exponent if exponent < 308.0 else math.inf


def _finite(interval: list[float]) -> list[float | None]:
    """Return the interval, or ``[None, None]`` (open) where its standard error is infinite."""
    if all(math.isfinite(e) for e in interval):
        return list(interval)
    return [None, None]


def fixed_across(
    space: Space, u: Uncertainty, v: np.ndarray, members: list[str]
) -> list[dict[str, object]]:
    """Name the combinations across an undetermined direction ``v``, with 95 % intervals.

    For an exact symmetry of parameters in logarithmic coordinates (the capacity and the
    two resistances of a thermal model, scaled by ``k`` and ``1/k``) these are the
    products the data fix: one member (the one that moves against the others, where one
    does; else the first) paired with each other one, with exponents that cancel ``v``
    (``C R1``, ``C R2``). For parameters in linear coordinates, the
    sums. Members of mixed coordinates (a log parameter made linear below its first
    levels, :meth:`.Space.near`, beside log ones) are combined as products, at the
    answer's relative changes: on OpenModelica's ``Mass_Damper`` the common scale of
    mass, stiffness and a damping made linear was found flat and named nothing fixed.
    Their standard errors come from the covariance with ``v``'s own variance
    projected out (along ``v`` it measured the solver's noise, not the data).
    """
    idx = [space.names.index(n) for n in members]
    if u.cov is None or len(idx) < 2:
        return []
    mixed = len({bool(space.log[j]) for j in idx}) > 1
    # decades of each coordinate per search unit: its width for a log one; for a mixed
    # member its relative change at the answer, as its own relative error is read
    per = np.array(space.width, dtype=float)
    if mixed:
        values = [float(u.values[space.names[j]]) for j in idx]
        if not all(x > 0 for x in values):
            return []
        for j, x in zip(idx, values, strict=True):
            per[j] = space.local_scale(j, x) / (x * math.log(10.0))
    log = mixed or bool(space.log[idx[0]])
    change = v * per  # how each working-domain value (or its log, for products) moves
    unit = v / max(float(np.linalg.norm(v)), 1e-300)
    keep = np.eye(space.dim) - np.outer(unit, unit)
    t = quantile(max(min(u.dof.values(), default=1.0), 1.0))
    # the pivot is the member that moves against the others (C against R1 and R2), so
    # that each pair is a product, R1 C and R2 C, not a ratio of two that move together
    signs = [1 if change[j] > 0 else -1 for j in idx]
    first = next((j for j, g in zip(idx, signs, strict=True) if signs.count(g) == 1), idx[0])
    out = []
    for j in [i for i in idx if i != first]:
        a = {first: 1.0, j: _rounded(-float(change[first] / change[j]))}
        names = [space.names[i] for i in a]
        g = np.zeros(space.dim)
        for i, coef in a.items():
            g[i] = coef * per[i]
        se = math.sqrt(u.variance(keep @ g))
        values = [u.values[n] for n in names]
        coefficients = {space.names[i]: float(coef) for i, coef in a.items()}
        if log and all(x > 0 for x in values):
            level = sum(coef * math.log10(u.values[space.names[i]]) for i, coef in a.items())
            name = " ".join(f"{space.names[i]}{_exponent(coef)}" for i, coef in a.items())
            interval = [_pow10(level - t * se), _pow10(level + t * se)]
            out.append({"name": name, "value": _pow10(level), "interval": _finite(interval),
                        "form": "product", "coefficients": coefficients})  # fmt: skip
        elif not log:
            level = sum(coef * u.values[space.names[i]] for i, coef in a.items())
            name = " ".join(f"{coef:+.3g} {space.names[i]}" for i, coef in a.items())
            interval = [level - t * se, level + t * se]
            out.append({"name": name, "value": level, "interval": _finite(interval),
                        "form": "sum", "coefficients": coefficients})  # fmt: skip
    return out
