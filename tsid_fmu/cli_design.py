"""``tsid design STUDY --result DIR``: the experiment to run next, or why none helps.

Prints the verdict and the table of intervals (the study's, and predicted with the
proposal); writes ``design_input.csv`` (the input to replay on the rig),
``design.png``, ``design.json``, ``design.md`` and ``design.html`` to the output folder
(default ``<result>.design/`` beside the result folder ``<result>``, checked before any
simulation; the folder is replaced as a whole). ``--json`` prints ``design.json``'s
content instead of the table. Errors are the package's own (exit 2, one line).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from tsid_fmu.cli_values import timeout_seconds, worker_count

__all__ = ["add_design_parser"]


def _cmd_design(args: argparse.Namespace) -> int:
    from tsid_fmu.design import design, write_design
    from tsid_fmu.design.files import check_output, default_output
    from tsid_fmu.load import load

    folder = Path(args.result)
    result = load(folder, args.study)
    # before any simulation: a design that cannot be written is not computed
    out = check_output(Path(args.out) if args.out else default_output(folder), folder)
    shown = not args.quiet and sys.stderr.isatty()
    found = design(result, workers=args.workers, timeout=args.timeout,
                   progress=(lambda line: print(f"design: {line}", file=sys.stderr,
                                                flush=True)) if shown else None)  # fmt: skip
    for warning in found.warnings:
        print(f"tsid: warning: {warning}", file=sys.stderr)
    files = write_design(found, out)
    if args.json:
        print(json.dumps(found.to_dict(), indent=1, allow_nan=False))
        return 0
    print(found.text())  # aligned columns for a terminal; design.md has the markdown
    print("wrote " + ", ".join(str(p) for p in files))
    return 0


def add_design_parser(sub: Any) -> None:
    """Add ``tsid design`` to the sub-commands."""
    p = sub.add_parser(
        "design",
        help="propose the experiment that determines what a study left open",
        description="From a finished identification, propose the input (inside the study "
        "file's [design] limits: amplitudes, band, duration, signal kinds) that best "
        "determines what the data left weak, with the intervals the study plus it would "
        "give; or report that no input of that kind separates some parameters, naming "
        "what the data do fix.",
    )
    p.add_argument("study", help="study file (TOML), with an optional [design] table")
    p.add_argument("--result", required=True, metavar="DIR", help="the study's results folder")
    p.add_argument(
        "-o", "--out", help="output folder, replaced as a whole (default: DIR.design beside DIR)"
    )
    p.add_argument("--workers", type=worker_count, metavar="N", help="worker processes")
    p.add_argument("--timeout", type=timeout_seconds, metavar="SECONDS", help="per simulation")
    p.add_argument("--json", action="store_true", help="print design.json on stdout")
    p.add_argument(
        "-q", "--quiet", action="store_true", help="no progress lines or library warnings on stderr"
    )
    p.set_defaults(func=_cmd_design)
