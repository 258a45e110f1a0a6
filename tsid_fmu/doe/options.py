"""Thresholds and rules of re-leveling (the ``[leveling]`` table of a study)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from tsid_fmu.errors import StudyError

__all__ = ["LevelingOptions"]


@dataclass(frozen=True)
class LevelingOptions:
    """Thresholds and rules of re-leveling.

    Parameters
    ----------
    significance_db : float
        A factor whose S/N main effect spans less than this (max - min of the level
        means, in dB) is *flat*. Default 0.1 dB, i.e. about a 2.3 % change of the RMS cost
        across the levels.
    tolerance : float
        A range is *small* once ``(max - min) / |centre|`` of its levels is at most this.
        Default 0.005 (levels within +/-0.25 % of the centre).
    shrink : float
        Reduction rate: factor applied to the half-width of a range that is narrowed
        (Case 1 with an interior best, Case 2). Default 0.5.
    n_levels : int or None
        Number of levels of later iterations; default: as many as the first iteration
        for parameters, three for rotated factors.
    refine : bool
        If true, an interior best is refined by the vertex of a parabola through the S/N
        of the best level and its two neighbours (clipped to between them).
    selective : bool
        MISO paper's Case II: flat factors keep their levels while any factor is still
        significant. Default false (SISO paper: flat and wide ranges are narrowed).
    scale : {"auto", "linear", "log"}
        Spacing of generated levels. ``auto`` spaces logarithmically when all levels are
        positive and the range spans at least a factor ``log_ratio``.
    log_ratio : float
        Ratio max/min from which ``auto`` uses logarithmic spacing. Default 10 (a range
        spanning a decade or more).
    stall : int
        Case 3 also holds when every S/N has been flat for this many iterations in a row
        while the best cost fell by less than ``stall_rtol``: the levels then sit in a
        valley the data hardly determine, and narrowing it further changes nothing the
        data can tell. 0 turns the rule off. Default 2.
    stall_rtol : float
        Relative fall of the best cost below which an iteration counts as not improving.
        Default 1e-4.
    expand : float
        Factor applied to the half-width when a range moves because its best is on the
        boundary (Case 1, shift): the new range is centred on that boundary level. 1
        keeps the width, below 1 narrows as the SISO paper's Tables I-III do, above 1
        recovers faster from a range narrowed too early. Default 1.
    min_contribution : float
        ANOVA percent contribution below which a factor is treated as flat when
        choosing new levels, even if its S/N moves by more than ``significance_db``
        (its apparent effect is then mostly other factors' interactions). With
        ``selective`` such a factor keeps its range until the dominant ones have
        settled. Default 0 (off). The stop rule (Case 3) uses ``significance_db`` only.
    """

    significance_db: float = 0.1
    tolerance: float = 0.005
    shrink: float = 0.5
    n_levels: int | None = None
    refine: bool = True
    selective: bool = False
    scale: str = "auto"
    log_ratio: float = 10.0
    min_contribution: float = 0.0
    expand: float = 1.0
    stall: int = 2
    stall_rtol: float = 1e-4

    def __post_init__(self) -> None:
        checks = [
            (
                math.isfinite(self.significance_db) and self.significance_db >= 0,
                f"significance_db must be >= 0 (and finite), got {self.significance_db}",
            ),
            (
                math.isfinite(self.tolerance) and self.tolerance > 0,
                f"tolerance must be > 0 (and finite), got {self.tolerance}",
            ),
            (0 < self.shrink < 1, f"shrink must be between 0 and 1, got {self.shrink}"),
            (
                self.n_levels is None or 2 <= self.n_levels <= 5,
                "n_levels must be from 2 to 5 (the standard arrays have 2-, 3-, 4- and "
                f"5-level columns), got {self.n_levels}",
            ),
            (
                self.scale in ("auto", "linear", "log"),
                f"scale must be 'auto', 'linear' or 'log', got {self.scale!r}",
            ),
            (
                math.isfinite(self.log_ratio) and self.log_ratio > 1,
                f"log_ratio must be > 1, got {self.log_ratio}",
            ),
            (
                math.isfinite(self.expand) and self.expand > 0,
                f"expand must be > 0, got {self.expand}",
            ),
            (
                isinstance(self.stall, int)
                and not isinstance(self.stall, bool)
                and self.stall >= 0,
                f"stall must be an integer >= 0, got {self.stall!r}",
            ),
            (
                math.isfinite(self.stall_rtol) and self.stall_rtol >= 0,
                f"stall_rtol must be a finite number >= 0, got {self.stall_rtol}",
            ),
            (
                0 <= self.min_contribution < 100,
                f"min_contribution must be a percentage in [0, 100), got {self.min_contribution}",
            ),
        ]
        for ok, message in checks:
            if not ok:
                raise StudyError(message)
