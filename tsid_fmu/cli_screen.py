"""``tsid screen STUDY``: sensitivity screening before an identification.

Prints the two rankings side by side (Morris or Sobol, and the MISO paper's eq. 7 from
an L25), the parameters set apart and where the two disagree; writes ``screening.csv``
(every index), ``screening.json`` (the whole result) and ``screening.png`` (a bar plot of
the ranking index per parameter, one group of bars per screened quantity) to the output
folder. Errors are the package's own (exit 2, one line) like every ``tsid`` command.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from tsid_fmu.cli_values import timeout_seconds, whole_at_least, worker_count

__all__ = ["add_screen_parser", "plot_screening", "write_screening"]


def _whole(text: str) -> int:
    """``--n``: a whole number of at least 2."""
    return whole_at_least(text, 2)


def plot_screening(result: Any, path: Path) -> Path:
    """Draw the ranking index (``mu*`` normalised, or ``ST``) per parameter and quantity."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    key = result.index_name
    names, quantities = result.ranking(), result.quantities
    width = 0.8 / len(quantities)
    fig, ax = plt.subplots(figsize=(1.2 + 1.1 * len(names), 3.6))
    for i, q in enumerate(quantities):
        heights = [result.indices[q][n][key] for n in names]
        ax.bar(np.arange(len(names)) + (i - (len(quantities) - 1) / 2) * width, heights,
               width, label=q)  # fmt: skip
    ax.axhline(result.threshold, color="0.4", lw=0.8, ls="--", label="not felt below")
    ax.set_ylabel("mu* / largest mu*" if result.method == "morris" else "total Sobol index ST")
    ax.set_xticks(np.arange(len(names)), names)
    ax.set_title(f"{result.method} screening over the first ranges ({result.nfev} simulations)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_screening(result: Any, out: Path) -> list[Path]:
    """Write ``screening.csv``, ``screening.json`` and ``screening.png`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    csv = out / "screening.csv"
    result.to_pandas().to_csv(csv)
    js = out / "screening.json"
    js.write_text(json.dumps(result.to_dict(), indent=1), encoding="utf-8")
    return [csv, js, plot_screening(result, out / "screening.png")]


def _print(result: Any, files: list[Path]) -> None:
    import pandas as pd

    with pd.option_context("display.width", 200, "display.max_columns", 40):
        print(result.table().to_string(float_format=lambda v: f"{v:.3g}"))
    print(
        f"\n{result.method}, n={result.n}: {result.nfev} simulations "
        f"({result.nfev_screen} screening, {result.nfev_contribution} for eq. 7 on "
        f"{result.array or '-'})" + (f"; {result.failed} failed" if result.failed else "")
    )
    none = "none"
    print(f"set apart ({result.method}): {', '.join(result.set_apart) or none}")
    if result.array:
        print(f"set apart (eq. 7 < {result.min_percent:g} %): "
              f"{', '.join(result.contribution_set_apart) or none}")  # fmt: skip
    for note in result.disagreements():
        print(f"disagree: {note}")
    for warning in result.warnings:
        print(f"warning: {warning}")
    print("wrote " + ", ".join(str(p) for p in files))


def _cmd_screen(args: argparse.Namespace) -> int:
    from tsid_fmu.screening import screen

    out = Path(args.out) if args.out else Path(args.study).parent / "screening"
    result = screen(
        args.study,
        args.method,
        args.n,
        workers=args.workers,
        timeout=args.timeout,
        progress=not args.quiet and sys.stderr.isatty(),
        contribution=not args.no_contribution,
    )
    _print(result, write_screening(result, out))
    return 0


def add_screen_parser(sub: Any) -> None:
    """Add ``tsid screen`` to the sub-commands."""
    p = sub.add_parser(
        "screen",
        help="sensitivity screening over a study's first ranges (needs tsid-fmu[screen])",
        description="Morris (cheap: n (k+1) simulations) or Sobol (thorough: n (k+2)) "
        "through SALib over the study's first ranges, per output and for the cost, beside "
        "the MISO paper's eq. 7 from an L25; sets apart the parameters no output feels.",
    )
    p.add_argument("study", help="study file (TOML)")
    p.add_argument(
        "--method",
        choices=["morris", "sobol"],
        default="morris",
        help="Morris elementary effects (cheap, default) or Sobol indices (thorough)",
    )
    p.add_argument(
        "--n",
        type=_whole,
        metavar="N",
        help="Morris trajectories (default 20) or Sobol base samples (power of 2, default 64)",
    )
    p.add_argument(
        "-o", "--out", help="folder for screening.csv/.json/.png (default: screening/ beside it)"
    )
    p.add_argument("--workers", type=worker_count, metavar="N", help="worker processes")
    p.add_argument("--timeout", type=timeout_seconds, metavar="SECONDS", help="per simulation")
    p.add_argument("--no-contribution", action="store_true", help="skip eq. 7 (the L25)")
    p.add_argument(
        "-q", "--quiet", action="store_true", help="no progress display, no library warnings"
    )
    p.set_defaults(func=_cmd_screen)
