"""The generalisation benchmark's table and summary (``benchmarks/generalise.py``).

:func:`render` takes the rows of the runs (one per problem and variant) and returns the
per-problem table, the summary (success rates overall and per family, simulations of
tsid against ``least_squares`` from the centre, tsid's successes where
``least_squares`` failed, false convergences, wall time) and whether tsid meets the
``--check`` bar (success >= 95 % and median-sims ratio <= 2).
"""

import math
import statistics
from collections.abc import Sequence

import numpy as np

#: ``--check``: lowest acceptable success rate of tsid, highest sims ratio.
MIN_SUCCESS = 0.95
MAX_SIMS_RATIO = 2.0

COLUMNS = [
    "family",
    "seed",
    "var",
    "p",
    "tsid sims",
    "tsid ratio",
    "exit",
    "LS-c sims",
    "LS-c ratio",
    "CMA sims",
    "CMA ratio",
    "LS-t ratio",
    "best/floor",
    "tsid ok, LS-c not",
    "s",
]


def _ratio(r: dict) -> str:
    mark = "" if r["ok"] else " x"
    return f"{r['ratio']:.4g}{mark}"


def _cells(row: dict) -> list[str]:
    if "error" in row:
        return [row["family"], str(row["seed"]), row["variant"], "-", "ERROR " + row["error"]]
    m = row["methods"]
    rescue = "yes" if m["tsid"]["ok"] and not m["LS-c"]["ok"] else ""
    return [
        row["family"],
        str(row["seed"]),
        row["variant"],
        str(row["p"]),
        str(m["tsid"]["nfev"]),
        _ratio(m["tsid"]),
        str(m["tsid"]["status"]),
        str(m["LS-c"]["nfev"]),
        _ratio(m["LS-c"]),
        str(m["CMA"]["nfev"]),
        _ratio(m["CMA"]),
        _ratio(m["LS-t"]),
        f"{row.get('best_over_floor', math.nan):.3g}",
        rescue,
        f"{row['time']:.0f}",
    ]


def _table(rows: Sequence[dict], markdown: bool) -> list[str]:
    cells = [_cells(r) for r in rows]
    if markdown:
        lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
        return lines + ["| " + " | ".join(c) + " |" for c in cells]
    widths = [
        max([len(h)] + [len(c[i]) for c in cells if i < len(c)]) for i, h in enumerate(COLUMNS)
    ]
    fmt = lambda c: "  ".join(v.rjust(widths[i]) for i, v in enumerate(c))  # noqa: E731
    return [fmt(COLUMNS), *(fmt(c) for c in cells)]


def _rate(ok: list[bool]) -> str:
    return f"{sum(ok)}/{len(ok)} ({100 * sum(ok) / len(ok):.0f} %)" if ok else "-"


def _refit(tsid: dict) -> bool:
    """Whether tsid's reported cost differs from the benchmark's evaluation of its answer."""
    return abs(tsid["fun"] - tsid["cost"]) > 1e-6 * max(abs(tsid["cost"]), 1e-300)


def _median(values: list[int]) -> float:
    return float(statistics.median(values)) if values else float("nan")


def _group_line(name: str, rows: Sequence[dict], methods: Sequence[str]) -> tuple[str, float]:
    """One summary line: success per method, median sims of tsid / LS-c; and that ratio."""
    rates = ", ".join(f"{m} {_rate([r['methods'][m]['ok'] for r in rows])}" for m in methods)
    tsid = _median([r["methods"]["tsid"]["nfev"] for r in rows])
    ls = _median([r["methods"]["LS-c"]["nfev"] for r in rows])
    ratio = tsid / ls if ls else float("inf")
    return (
        f"{name:<14} success: {rates}; median sims tsid {tsid:g} / LS-c {ls:g} = {ratio:.2f}",
        ratio,
    )


def _mismatch(row: dict) -> bool:
    """Whether the draw put a model mismatch into the data (its notes say which)."""
    note = str(row.get("notes", {}).get("mismatch", "none"))
    return not note.startswith("none")


def coverage_lines(rows: Sequence[dict]) -> list[str]:
    """Share of true values inside tsid's 95 % intervals, per family, split three ways:
    no mismatch drawn; mismatch drawn and the intervals flagged; mismatch drawn and not
    flagged (a miss there is silent). Also the share of all parameters that miss silently."""

    def cell(rs: Sequence[dict]) -> str:
        hits = [v for r in rs for v in r["methods"]["tsid"]["coverage"]["inside"].values()]
        return f"{sum(hits)}/{len(hits)}" if hits else "-"

    done = [r for r in rows if "error" not in r and "coverage" in r["methods"]["tsid"]]
    if not done:
        return []
    flagged = lambda r: r["methods"]["tsid"]["coverage"]["flagged"]  # noqa: E731
    groups = {
        "no mismatch": [r for r in done if not _mismatch(r)],
        "mismatch, flagged": [r for r in done if _mismatch(r) and flagged(r)],
        "mismatch, silent": [r for r in done if _mismatch(r) and not flagged(r)],
    }
    lines = ["", "Coverage: true values inside tsid's 95 % intervals (per parameter)"]
    lines.append(f"{'family':<14} " + "  ".join(f"{k:>18}" for k in groups))
    for family in [*dict.fromkeys(r["family"] for r in done), "all"]:
        cells = [cell([r for r in g if family in ("all", r["family"])]) for g in groups.values()]
        lines.append(f"{family:<14} " + "  ".join(f"{c:>18}" for c in cells))
    every = [v for r in done for v in r["methods"]["tsid"]["coverage"]["inside"].values()]
    silent = [
        v
        for r in groups["mismatch, silent"]
        for v in r["methods"]["tsid"]["coverage"]["inside"].values()
        if not v
    ]
    false_alarm = [flagged(r) for r in groups["no mismatch"]]
    reach = [
        v for r in groups["no mismatch"] for v in r["methods"]["tsid"]["coverage"]["reach"].values()
    ]
    if reach:  # calibrated 95 % intervals: |t| / 1.96 has a median of 0.34
        lines.append(
            f"no mismatch: median error / interval half-width {statistics.median(reach):.2f} "
            "(0.34 for calibrated 95 % intervals: lower is conservative)"
        )
    lines += _calibration_lines(groups["no mismatch"])
    lines.append(
        f"silent misses (outside the interval, not flagged): {len(silent)} of {len(every)} "
        f"parameters ({100 * len(silent) / max(len(every), 1):.1f} %); flagged without a "
        f"mismatch drawn: {_rate(false_alarm)}"
    )
    return lines


def _calibration_lines(rows: Sequence[dict]) -> list[str]:
    """Calibration without a mismatch: coverage split into estimated intervals and those
    at the profile's resolution (reported as bounds), the data sets they come from, and
    the errors in standard errors of the hand studies (one answer per data set: a data
    set's ``tsid init`` answer is nearly the same, and its parameters are correlated, so
    the values are not independent and the share inside moves by more than a binomial
    over parameters would)."""
    kinds: dict[str, list[bool]] = {"estimates": [], "resolution bounds": []}
    z: list[float] = []
    for r in rows:
        cov = r["methods"]["tsid"]["coverage"]
        for name, hit in cov["inside"].items():
            d = cov.get("detail", {}).get(name, {})
            kinds["resolution bounds" if d.get("bound") else "estimates"].append(bool(hit))
            if r["variant"] == "hand" and not d.get("bound") and d.get("z") is not None:
                z.append(abs(float(d["z"])))
    sets = len({(r["family"], r["seed"]) for r in rows})
    out = [
        f"no mismatch, {kind}: {sum(h)}/{len(h)} inside ({100 * sum(h) / len(h):.1f} %)"
        for kind, h in kinds.items()
        if h
    ]
    if z:
        a = np.asarray(z)
        out.append(
            f"no mismatch, {sets} data sets; |error| / standard error of the hand studies' "
            f"estimates ({a.size}): median {np.median(a):.2f} (0.67 calibrated), within 1 "
            f"{100 * np.mean(a < 1):.0f} % (68 %), "
            f"within 1.96 {100 * np.mean(a < 1.96):.0f} % (95 %)"
        )
    return out


def rounds_lines(rows: Sequence[dict]) -> list[str]:
    """Median rounds of parallel simulation (the wall time in simulations) at 1, 4 and
    16 workers, tsid against ``least_squares`` from the centre."""
    done = [
        r for r in rows if r["methods"]["tsid"].get("rounds") and "rounds" in r["methods"]["LS-c"]
    ]
    if not done:
        return []
    lines = ["", "Rounds of parallel simulation (median over runs; the wall time in simulations)"]
    for w in ("1", "4", "16"):
        tsid = _median([r["methods"]["tsid"]["rounds"][w] for r in done])
        ls = _median([r["methods"]["LS-c"]["rounds"][w] for r in done])
        ratio = tsid / ls if ls else float("inf")
        lines.append(f"  {w:>2} workers: tsid {tsid:g} / LS-c {ls:g} = {ratio:.2f}")
    return lines


def where_lines(rows: Sequence[dict]) -> list[str]:
    """Where tsid's simulations go: the median and the total of each part, and the
    share of runs that spend any on it."""
    done = [r for r in rows if "where" in r["methods"]["tsid"]]
    if not done:
        return []
    parts = list(done[0]["methods"]["tsid"]["where"])
    lines = ["", "Where tsid's simulations go (median over runs / total / runs spending any)"]
    for part in parts:
        spent = [r["methods"]["tsid"]["where"].get(part, 0) for r in done]
        lines.append(
            f"  {part:<10} {_median(spent):>7g} {sum(spent):>8d} "
            f"{sum(v > 0 for v in spent):>4d}/{len(spent)}"
        )
    return lines


def summary(rows: Sequence[dict], wall: float) -> tuple[list[str], bool]:
    """The summary lines and whether tsid meets the ``--check`` bar."""
    done = [r for r in rows if "error" not in r]
    errors = len(rows) - len(done)
    if not done:
        return [f"no problem ran ({errors} errors); wall time {wall:.0f} s"], False
    methods = [m for m in ("tsid", "LS-c", "CMA", "DE") if m in done[0]["methods"]]
    lines = ["", "Summary (success: final cost <= 1.001 x the lowest any method found)"]
    line, ratio = _group_line("all", done, methods)
    lines.append(line)
    for variant in ("hand", "init"):
        group = [r for r in done if r["variant"] == variant]
        if group:
            lines.append(_group_line(f"  {variant}", group, methods)[0])
    for family in dict.fromkeys(r["family"] for r in done):
        lines.append(_group_line(family, [r for r in done if r["family"] == family], methods)[0])
    ls_failed = [r for r in done if not r["methods"]["LS-c"]["ok"]]
    rescued = [r["methods"]["tsid"]["ok"] for r in ls_failed]
    false_conv = [
        r for r in done if r["methods"]["tsid"]["status"] == 0 and not r["methods"]["tsid"]["ok"]
    ]
    tsid_ok = [r["methods"]["tsid"]["ok"] for r in done]
    lines += where_lines(done)
    lines += rounds_lines(done)
    lines += coverage_lines(done)
    lines += [
        f"tsid succeeded where LS-c failed: {_rate(rescued)}",
        f"tsid false convergence (exit 0, not a success): {len(false_conv)} of {len(done)}",
        "tsid's own cost differs from the benchmark's re-evaluation (> 1e-6) in "
        f"{sum(_refit(r['methods']['tsid']) for r in done)} of {len(done)}",
        f"errors: {errors}; total wall time {wall:.0f} s",
    ]
    success = sum(tsid_ok) / len(tsid_ok)
    verdict = errors == 0 and success >= MIN_SUCCESS and ratio <= MAX_SIMS_RATIO
    lines.append(
        f"check (tsid success >= {100 * MIN_SUCCESS:.0f} %, sims ratio <= {MAX_SIMS_RATIO:g}): "
        + ("pass" if verdict else "FAIL")
    )
    return lines, verdict


def render(
    rows: Sequence[dict], wall: float, *, markdown: bool, seeds: str, workers: int
) -> tuple[str, bool]:
    """The whole report (table, then summary) and the ``--check`` verdict."""
    head = [f"Generalisation benchmark, {seeds} seeds, {workers} worker(s)", ""]
    lines, verdict = summary(rows, wall)
    notes = ["", "Drawn per problem (hand variant's ranges: placement/style):"]
    for r in rows:
        if "notes" in r and r["variant"] == "hand":
            notes.append(
                f"  {r['family']} {r['seed']}: "
                + "; ".join(f"{k} {v}" for k, v in r["notes"].items())
            )
    return "\n".join(head + _table(rows, markdown) + lines + notes), verdict
