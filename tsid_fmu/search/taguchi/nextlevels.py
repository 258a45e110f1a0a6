"""Step IV for a frame: the papers' re-leveling cases, then the factors of the next frame.

For parameters (axis-aligned factors) the decision is exactly the papers'
:func:`tsid_fmu.doe.leveling.relevel`, in parameter units. For rotated factors the same
rules (:func:`tsid_fmu.doe.rules.decide_factor`) act on each factor's offsets. Either way
each factor gets a case, a centre and a half-width. When the next frame is rotated, its
factors are the principal axes of the cost surface (:mod:`tsid_fmu.search.taguchi.surface`),
and their half-widths are the extent, along each new axis, of the box of half-widths
just decided (the ellipsoid ``sum_k h_k^2 d_k d_k^T``), at most the first levels' range.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tsid_fmu.doe.leveling import LevelingDecision, relevel
from tsid_fmu.doe.options import LevelingOptions
from tsid_fmu.doe.rules import FactorState, decide_factor
from tsid_fmu.numerics.tuning import GROWTH, MAX_HALF_WIDTH, POSITIVE_MARGIN, ROTATED_LEVELS
from tsid_fmu.search.space import Space
from tsid_fmu.search.taguchi.frame import Factor, Frame

__all__ = ["MAX_HALF_WIDTH", "next_frame"]


def _rotated_decisions(
    frame: Frame,
    space: Space,
    sn_means: Mapping[str, list[float]],
    centre_s: np.ndarray,
    centre_label: str,
    options: LevelingOptions,
    contribution: Mapping[str, float],
) -> LevelingDecision:
    spans = frame.spans(space)
    deltas = {}
    for f in frame.factors:
        sn = np.asarray(sn_means[f.name], dtype=float)
        finite = sn[np.isfinite(sn)]
        deltas[f.name] = float(finite.max() - finite.min()) if finite.size else 0.0
    flat = {n: d < options.significance_db for n, d in deltas.items()}
    small = {n: spans[n] <= options.tolerance for n in deltas}
    minor = {n: contribution.get(n, 100.0) < options.min_contribution for n in deltas}
    converged = all(flat.values()) and all(small.values())
    choose_flat = {n: flat[n] or minor[n] for n in deltas}
    any_significant = not all(choose_flat.values())
    z = frame.coordinates(centre_s)
    decisions = []
    for k, f in enumerate(frame.factors):
        state = FactorState(
            choose_flat[f.name], small[f.name], minor[f.name], any_significant, converged
        )
        text = (
            f"ANOVA contribution {contribution.get(f.name, 100.0):.2g} %" if minor[f.name] else ""
        )
        decision, centre_z, half = decide_factor(
            f.name,
            np.asarray(f.offsets),
            np.asarray(sn_means[f.name], dtype=float),
            state,
            options,
            centre=(float(z[k]), f"{centre_label} (offset {z[k]:+.4g})"),
            minor_text=text,
        )
        n = options.n_levels or ROTATED_LEVELS
        decision.optimum = float(centre_z)
        decision.levels = [float(v) for v in np.linspace(-half, half, n)]
        decision.reason += f"; next half-width {half:.4g} (was {f.half_width:.4g})"
        decisions.append(decision)
    if converged:
        message = "Case 3: every S/N is flat and every range is within the tolerance"
    elif any_significant:
        moving = [d.name for d in decisions if d.case in ("recentre", "shift")]
        message = "Case 1: S/N changes significantly for " + (", ".join(moving) or "none")
    else:
        message = "Case 2: every S/N is flat but some levels are still far apart"
    return LevelingDecision(parameters=decisions, converged=converged, message=message)


def _half_widths(frame: Frame, space: Space, decision: LevelingDecision) -> list[float]:
    """Half-width along each current factor's direction that the decision chose."""
    out = []
    for k, (f, d) in enumerate(zip(frame.factors, decision.parameters, strict=True)):
        if f.values is not None:
            s = [space.coordinate(k, v) for v in d.levels]
            out.append(0.5 * (max(s) - min(s)))
        else:
            out.append(0.5 * (max(d.levels) - min(d.levels)))
    return out


def _rotated_frame(
    frame: Frame,
    space: Space,
    *,
    decision: LevelingDecision,
    centre_x: dict[str, float],
    axes: tuple[np.ndarray, np.ndarray] | None,
    options: LevelingOptions,
) -> Frame:
    """Make the next frame: rotated factors in coordinates anchored at the new centre.

    The box of half-widths decided for the current factors is carried into the new
    coordinates (scaled by the ratio of the two coordinates' local scales at the new
    centre), then measured along each new axis.
    """
    old, new = frame.coords(space), space.anchored(centre_x)
    scale = np.array(
        [
            old.local_scale(j, centre_x[n]) / new.local_scale(j, centre_x[n])
            for j, n in enumerate(space.names)
        ]
    )
    half = _half_widths(frame, space, decision)
    box = sum(
        (
            h * h * np.outer(scale * f.direction, scale * f.direction)
            for h, f in zip(half, frame.factors, strict=True)
        ),
        np.zeros((space.dim, space.dim)),
    )
    if axes is not None:
        directions, curvature = axes
    else:
        directions = np.column_stack([scale * f.direction for f in frame.factors])
        directions /= np.linalg.norm(directions, axis=0)
        curvature = None
    prefix = "Z" if any(n.startswith("A") and n[1:].isdigit() for n in space.names) else "A"
    widths = _widths(directions, curvature, box, frame, half, scale)
    widths = np.minimum(widths, _positive_limit(space, new, centre_x, directions))
    factors = []
    for k in range(directions.shape[1]):
        n = options.n_levels or ROTATED_LEVELS
        factors.append(
            Factor(
                f"{prefix}{k + 1}", directions[:, k].copy(), np.linspace(-widths[k], widths[k], n)
            )
        )
    note = (
        "rotated factors: principal axes of the cost surface the runs show"
        if axes is not None
        else "rotated factors kept from the previous iteration"
    )
    return Frame(centre=np.zeros(space.dim), factors=factors, note=note, anchor=dict(centre_x))


def _positive_limit(
    space: Space, coords: Space, centre_x: Mapping[str, float], directions: np.ndarray
) -> np.ndarray:
    """Largest half-width of each rotated factor that keeps log parameters positive."""
    limit = np.full(directions.shape[1], np.inf)
    for j, n in enumerate(space.names):
        if not space.log[j]:
            continue
        room = POSITIVE_MARGIN * abs(centre_x[n]) / coords.width[j]
        with np.errstate(divide="ignore"):
            limit = np.minimum(limit, room / np.abs(directions[j]))
    return limit


def _widths(
    directions: np.ndarray,
    curvature: np.ndarray | None,
    box: np.ndarray,
    frame: Frame,
    half: list[float],
    scale: np.ndarray,
) -> np.ndarray:
    """Half-widths of the new factors.

    With the surface's curvatures, each new factor gets the half-width at which the
    surface predicts the same rise of the cost, the geometric mean of the rises the
    decided box gives along the current factors (so a flat combination gets wide
    levels, a stiff one narrow levels); without them, the box's extent along each
    direction. Never more than :data:`MAX_HALF_WIDTH`.
    """
    extent = np.sqrt(np.maximum(np.einsum("ik,ij,jk->k", directions, box, directions), 0.0))
    if curvature is None:
        out = extent
    else:
        hess = directions @ np.diag(curvature) @ directions.T
        along = np.array(
            [(scale * f.direction) @ hess @ (scale * f.direction) for f in frame.factors]
        )
        rise = float(np.exp(np.mean(np.log(np.maximum(along * np.square(half), 1e-300)))))
        top = max(float(curvature.max()), 1e-300)
        out = np.sqrt(rise / np.maximum(curvature, 1e-12 * top))
        # the cases decided the box: a new factor may widen at most GROWTH times over it
        out = np.minimum(out, GROWTH * extent)
    return np.clip(out, 1e-12, MAX_HALF_WIDTH)


def next_frame(
    frame: Frame,
    space: Space,
    sn_means: Mapping[str, list[float]],
    centre: tuple[dict[str, float], str] | None,
    options: LevelingOptions,
    contribution: Mapping[str, float],
    axes: tuple[np.ndarray, np.ndarray] | None,
) -> tuple[LevelingDecision, Frame]:
    """Decide the cases of an iteration's factors and make the next frame.

    Parameters
    ----------
    frame : Frame
        The iteration's factors.
    space : Space
        Search coordinates.
    sn_means : mapping
        Mean S/N per level of each factor.
    centre : (dict, str) or None
        The parameter set the next levels are centred on and its label (``"run 7"``,
        ``"predicted optimum"``); None centres each parameter on its best S/N level
        (SISO paper, axis-aligned frames only).
    options : LevelingOptions
        Re-leveling rules.
    contribution : mapping
        ANOVA percent contribution of each factor.
    axes : (numpy.ndarray, numpy.ndarray) or None
        Principal axes (columns) and curvatures of the cost surface, in coordinates
        anchored at the centre, for a rotated next frame; or None to keep the kind of
        frame (axis-aligned stays axis-aligned, rotated keeps its directions).

    Returns
    -------
    decision : LevelingDecision
        One decision per factor of ``frame``, with its reason.
    frame : Frame
        The factors and levels of the next iteration.
    """
    if frame.axis_aligned:
        decision = relevel(
            frame.level_values(space),
            sn_means,
            options,
            bounds=space.bounds,
            centre=None if centre is None else centre[0],
            contribution=contribution,
            centre_label=centre[1] if centre else "the best run",
        )
        if axes is None:
            return decision, Frame.from_levels(space, decision.next_levels())
    else:
        if centre is None:
            raise ValueError("a rotated frame needs a centre")
        centre_s = frame.coords(space).to_s(centre[0])
        decision = _rotated_decisions(
            frame, space, sn_means, centre_s, centre[1], options, contribution
        )
    centre_x = centre[0] if centre is not None else frame.coords(space).to_x(frame.centre)
    return decision, _rotated_frame(
        frame, space, decision=decision, centre_x=centre_x, axes=axes, options=options
    )
