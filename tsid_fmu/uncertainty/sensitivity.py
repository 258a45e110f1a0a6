"""Output sensitivities at the answer, by central differences in the search coordinates.

The derivative of every simulated output sample with respect to each parameter's search
coordinate (``log10`` of the value for parameters whose ranges span decades, the value
otherwise; :mod:`tsid_fmu.numerics.space`), for the measured inputs. The ``2p + 1``
simulations go to the evaluator as one batch, so a parallel evaluator runs them side by
side.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from tsid_fmu.errors import one_line
from tsid_fmu.evaluate.protocol import Evaluator
from tsid_fmu.evaluate.spec import EvaluationSpec
from tsid_fmu.numerics.space import Space
from tsid_fmu.numerics.tuning import SENSITIVITY_STEP as STEP

__all__ = ["STEP", "Sensitivities", "residual_jacobian", "sensitivities"]


@dataclass
class Sensitivities:
    """Residuals and their derivatives at a parameter set.

    Attributes
    ----------
    names : list of str
        The parameters, in the order of the columns of ``jacobian``.
    residuals : list of numpy.ndarray
        ``simulated - measured`` of each experiment, ``(n, outputs)``.
    jacobian : list of numpy.ndarray
        Per experiment ``(n, outputs, parameters)``: derivative of the outputs with
        respect to each parameter's search coordinate.
    experiments : list of str
        Experiment names.
    output_names : list of list of str
        Output names per experiment.
    """

    names: list[str]
    residuals: list[np.ndarray]
    jacobian: list[np.ndarray]
    experiments: list[str]
    output_names: list[list[str]]


def sensitivities(
    evaluator: Evaluator,
    spec: EvaluationSpec,
    space: Space,
    x: Mapping[str, float],
    *,
    step: float = STEP,
    failures: list[str] | None = None,
) -> Sensitivities | None:
    """Compute the output sensitivities at ``x`` (``None`` if they cannot be computed).

    A step that would leave a parameter's bounds is taken one-sided, and so is one
    whose simulation on the other side failed (an FMU's assertion just past the
    answer). They cannot be computed where the simulation at ``x`` fails, or both
    sides of some parameter do; ``failures`` then receives why, one line per cause.
    """
    s0 = space.to_s(x)
    sets, ends = [dict(x)], []
    for j in range(space.dim):
        up = min(s0[j] + step, max(space.s_upper[j], s0[j]))
        down = max(s0[j] - step, min(space.s_lower[j], s0[j]))
        ends.append((up, down))
        for value in (up, down):
            sets.append({**x, space.names[j]: space.value(j, value)})
    runs = evaluator.simulate(sets)
    ok = [all(sim.outputs is not None for sim in row) for row in runs]
    why = failures if failures is not None else []
    if not ok[0]:
        why.append(f"the simulation at the answer failed: {_error(runs[0])}")
        return None
    pairs = []  # per parameter: the two runs differenced and the distance between them
    for j, (up, down) in enumerate(ends):
        i_up, i_down = 1 + 2 * j, 2 + 2 * j
        hi = (i_up, up) if ok[i_up] else (0, float(s0[j]))
        lo = (i_down, down) if ok[i_down] else (0, float(s0[j]))
        if hi[1] - lo[1] <= 0:
            if ok[i_up] and ok[i_down]:
                why.append(f"no difference for {space.names[j]}: its bounds leave no step")
            else:
                failed = runs[i_down] if ok[i_up] else runs[i_up]
                why.append(
                    f"no difference for {space.names[j]}: the simulations beside the "
                    f"answer failed ({_error(failed)})"
                )
            return None
        pairs.append((hi[0], lo[0], hi[1] - lo[1]))
    base = runs[0]
    residuals, jac = [], []
    for e, exp in enumerate(spec.experiments):
        # the scored samples only, weighted as the evaluator's residuals are
        residuals.append(exp.weighted(base[e].outputs - exp.measured))  # type: ignore[operator]
        cols = [
            exp.weighted((runs[a][e].outputs - runs[b][e].outputs) / span)  # type: ignore[operator]
            for a, b, span in pairs
        ]
        jac.append(np.stack(cols, axis=-1))
    return Sensitivities(
        names=list(space.names),
        residuals=residuals,
        jacobian=jac,
        experiments=[e.name for e in spec.experiments],
        output_names=[list(e.output_names) for e in spec.experiments],
    )


def _error(row: list) -> str:
    """Return the first error of a row of simulations, on one line."""
    return one_line(
        next((sim.error for sim in row if sim.outputs is None), None) or "no reason given"
    )


def residual_jacobian(
    sens: Sensitivities,
    spec: EvaluationSpec,
    space: Space | None = None,
    x: Mapping[str, float] | None = None,
) -> np.ndarray:
    """Return the Jacobian of the least-squares residuals, one row per residual.

    The residuals are those the evaluator gives and the refinement minimises:
    ``(simulated - measured) / scale`` of every experiment of ``spec`` on its measured
    inputs, each experiment's ``(n, outputs)`` block flattened row by row (sample after
    sample, the outputs of a sample side by side), the experiments one after another.

    Parameters
    ----------
    sens : Sensitivities
        The output sensitivities at ``x`` (central differences, :func:`sensitivities`).
    spec : EvaluationSpec
        The experiments of ``sens``, for their residual scales.
    space : Space, optional
        With ``x``: convert the columns from search coordinates to parameter units,
        dividing each by :meth:`~tsid_fmu.numerics.space.Space.local_scale` at ``x`` (the
        linearisation the standard errors use).
    x : mapping, optional
        The parameter set ``sens`` was computed at.

    Returns
    -------
    numpy.ndarray
        Shape ``(n_residuals, len(sens.names))``, columns in the order of ``sens.names``;
        in search coordinates unless ``space`` and ``x`` are given.
    """
    blocks = [
        jac / e.scale[None, :, None] for e, jac in zip(spec.experiments, sens.jacobian, strict=True)
    ]
    out = np.vstack([b.reshape(-1, b.shape[-1]) for b in blocks])
    if space is not None and x is not None:
        scale = [space.local_scale(space.names.index(n), float(x[n])) for n in sens.names]
        out = out / np.asarray(scale)[None, :]
    return out
