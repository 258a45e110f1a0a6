"""Contribution analyses of the MISO paper (Section 3, Steps i and ii).

*Input contribution* (Step i): in experiments where one input acts alone, how much of
each output that input produces. The paper compares ranges (+/-150 N with +/-15 N);
experiments are ranked here by the RMS of the output about its mean (its energy), which
a short start-up transient hardly moves, and the range is reported beside it. The
subsystem of the main contributor is identified first.

*Parameter contribution* (Step ii): one-at-a-time variation. Each parameter takes three
values (of different orders of magnitude where the ranges are that wide) while the
others stay at their centre; the cost of each run gives the parameter's
"% of error variation" = (max - min of its costs) / (mean cost of all runs) x 100,
eq. (7) and Table 2. Parameters are then grouped by contribution and identified in
phases, the most influential group first.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from tsid_fmu.errors import StudyError

__all__ = [
    "Contribution",
    "InputContribution",
    "ParameterContribution",
    "group_parameters",
    "input_contribution",
    "oat_values",
    "parameter_contribution",
]


@dataclass
class Contribution:
    """What a ``contribution`` stage found, for the report (the phases are its plan).

    Attributes
    ----------
    input : dict or None
        The input contribution (Step i) as :class:`InputContribution`'s fields; None
        with one experiment.
    percent : dict
        Per experiment, each parameter's % of error variation (Step ii, eq. 7).
    runs : dict
        Per experiment, the one-at-a-time runs behind it.
    groups : dict
        Per experiment, the groups of parameters it fixed, most influential first.
    """

    input: dict[str, Any] | None = None
    percent: dict[str, dict[str, float]] = field(default_factory=dict)
    runs: dict[str, Any] = field(default_factory=dict)
    groups: dict[str, list[list[str]]] = field(default_factory=dict)


@dataclass
class InputContribution:
    """Size of each measured output in each single-input experiment.

    Attributes
    ----------
    experiments : list of str
        Experiment names, ranked by output RMS: the main contributor first.
    inputs : dict
        Experiment name -> the inputs that act in it.
    range : dict
        Experiment name -> peak-to-peak of its measured outputs (summed over outputs).
    rms : dict
        Experiment name -> RMS of its measured outputs (summed over outputs).
    """

    experiments: list[str]
    inputs: dict[str, list[str]]
    range: dict[str, float]
    rms: dict[str, float]

    def to_pandas(self) -> Any:
        """Return the table as a :class:`pandas.DataFrame`, main contributor first."""
        import pandas as pd

        rows = [
            {
                "experiment": e,
                "inputs": ", ".join(self.inputs[e]),
                "output range": self.range[e],
                "output RMS": self.rms[e],
                "share of RMS [%]": 100 * self.rms[e] / sum(self.rms.values()),
                "share of range [%] (paper)": 100 * self.range[e] / sum(self.range.values()),
            }
            for e in self.experiments
        ]
        return pd.DataFrame(rows).set_index("experiment")


def input_contribution(
    measured: Mapping[str, np.ndarray], inputs: Mapping[str, Sequence[str]]
) -> InputContribution:
    """Rank single-input experiments by the size of the output they produce.

    Parameters
    ----------
    measured : mapping of str to numpy.ndarray
        Experiment name -> measured outputs, shape ``(n,)`` or ``(n, k)``.
    inputs : mapping of str to sequence of str
        Experiment name -> the inputs that act in it.

    Returns
    -------
    InputContribution
        Ranges and RMS values, experiments ordered by decreasing output RMS.
    """
    rng: dict[str, float] = {}
    rms: dict[str, float] = {}
    for name, y in measured.items():
        y2 = np.asarray(y, dtype=float)
        y2 = y2[:, None] if y2.ndim == 1 else y2
        rng[name] = float(np.sum(np.ptp(y2, axis=0)))
        rms[name] = float(np.sum(np.sqrt(np.mean((y2 - y2.mean(axis=0)) ** 2, axis=0))))
    order = sorted(rms, key=lambda e: -rms[e])
    return InputContribution(
        experiments=order, inputs={e: list(inputs[e]) for e in order}, range=rng, rms=rms
    )


def oat_values(levels: Sequence[float]) -> list[float]:
    """Three values for a one-at-a-time variation: lowest, middle and highest level."""
    lv = sorted(float(v) for v in levels)
    return [lv[0], lv[len(lv) // 2], lv[-1]]


@dataclass
class ParameterContribution:
    """One-at-a-time runs and the "% of error variation" of each parameter.

    Attributes
    ----------
    runs : list of dict
        One entry per run: ``{"parameter", "values" (all parameters), "cost"}``.
    percent : dict
        Parameter -> % of error variation, eq. (7) of the MISO paper.
    centre : dict
        The centre values the other parameters keep.
    """

    runs: list[dict] = field(default_factory=list)
    percent: dict[str, float] = field(default_factory=dict)
    centre: dict[str, float] = field(default_factory=dict)

    def to_pandas(self) -> Any:
        """Return the runs (Table 2 of the MISO paper) as a :class:`pandas.DataFrame`."""
        import pandas as pd

        rows = []
        for i, run in enumerate(self.runs, start=1):
            row = {"run": i, "varied": run["parameter"]}
            row.update(run["values"])
            row["cost"] = run["cost"]
            row["% of error variation"] = self.percent[run["parameter"]]
            rows.append(row)
        return pd.DataFrame(rows).set_index("run")


def parameter_contribution(
    values: Mapping[str, Sequence[float]],
    centre: Mapping[str, float],
    costs: Sequence[float],
) -> ParameterContribution:
    """Compute the % of error variation of each parameter from one-at-a-time runs.

    Parameters
    ----------
    values : mapping of str to sequence of float
        The values each parameter takes, in run order (parameter by parameter).
    centre : mapping of str to float
        Value of each parameter while another one varies.
    costs : sequence of float
        Cost of each run, in the same order (``sum(len(v) for v in values)`` runs).

    Returns
    -------
    ParameterContribution
        Runs and percentages.
    """
    costs = np.asarray(costs, dtype=float)
    n = sum(len(v) for v in values.values())
    if costs.shape != (n,):
        raise StudyError(f"parameter contribution needs {n} costs, got {costs.shape}")
    finite = costs[np.isfinite(costs)]
    mean = float(finite.mean()) if finite.size else float("nan")
    out = ParameterContribution(centre=dict(centre))
    k = 0
    for name, vals in values.items():
        mine = costs[k : k + len(vals)]
        ok = mine[np.isfinite(mine)]
        spread = float(ok.max() - ok.min()) if ok.size else float("nan")
        out.percent[name] = 100.0 * spread / mean if mean and np.isfinite(mean) else float("nan")
        if ok.size < mine.size:
            out.percent[name] = float("inf")  # a failing value is as influential as it gets
        for v, c in zip(vals, mine, strict=True):
            run_values = dict(centre)
            run_values[name] = float(v)
            out.runs.append({"parameter": name, "values": run_values, "cost": float(c)})
        k += len(vals)
    return out


def group_parameters(
    percent: Mapping[str, float], ratio: float = 1.75, min_percent: float = 0.0
) -> list[list[str]]:
    """Group parameters of similar contribution, most influential group first.

    Parameters are sorted by decreasing contribution; a new group starts where a
    parameter's contribution is below ``1 / ratio`` of the previous one's (a gap).

    Parameters
    ----------
    percent : mapping of str to float
        % of error variation of each parameter.
    ratio : float
        Size of the gap that separates groups; default 1.75 (Table 2 of the MISO
        paper, 142 % and 94 % versus 48 % and 46 %, splits into {m1, K_s} and the rest).
    min_percent : float
        Parameters below this contribution are left out (returned as a last group only
        if they are all that is left).

    Returns
    -------
    list of list of str
        The groups.
    """
    if ratio <= 1:
        raise StudyError(f"group ratio must be > 1, got {ratio}")
    size = {n: 0.0 if np.isnan(p) else float(p) for n, p in percent.items()}
    groups: list[list[str]] = []
    minor: list[str] = []
    prev = None
    for name in sorted(size, key=lambda n: -size[n]):
        p = size[name]
        if p < min_percent:
            minor.append(name)
        elif groups and prev is not None and p * ratio >= prev:
            groups[-1].append(name)  # no gap: similar size, same group
            prev = p
        else:
            groups.append([name])
            prev = p
    if minor:
        groups.append(minor)
    return groups
