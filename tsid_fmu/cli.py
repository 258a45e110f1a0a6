"""Command line: ``tsid identify | simulate | info | build``.

Errors of the package (:class:`~tsid_fmu.errors.TsidError`) are printed as one line
naming what is wrong, with exit status 2; an interrupted study exits with 130 and says
how to resume.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path

from tsid_fmu.errors import StudyError, TsidError

__all__ = ["main"]


def _parse_assignments(items: Sequence[str], what: str) -> dict[str, str]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip() or not value.strip():
            raise StudyError(f"{what} must look like NAME=VALUE, got {item!r}")
        out[name.strip()] = value.strip()
    return out


def _cmd_identify(args: argparse.Namespace) -> int:
    from tsid_fmu.identify import identify

    out = Path(args.out) if args.out else Path(args.study).with_suffix("").parent / "results"
    result = identify(
        args.study,
        out,
        resume=args.resume,
        max_iterations=args.max_iterations,
        pause_after=args.pause_after,
        progress=not args.quiet,
        plots=not args.no_plots,
        continue_from_run=args.continue_from_run,
        workers=args.workers,
        timeout=args.timeout,
        scheduler=args.scheduler,
    )
    print(result.parameters_frame().to_string())
    print()
    print(result.stages_frame()[["kind", "cost", "simulations"]].to_string())
    print()
    print(result.message)
    print(f"cost {result.fun:.6g} on the measured inputs; {result.nfev} simulations")
    for warning in result.warnings:
        print(f"warning: {warning}")
    for name, reason in result.weak.items():
        print(f"weakly determined: {name}: {reason}")
    for name, v in result.validation.items():
        if "cost" in v:
            print(f"validation {name}: cost {v['cost']:.6g}")
    print(f"report, tables and plots: {out}/report.md")
    return {0: 0, 1: 1, 2: 3}[result.status]


def _cmd_simulate(args: argparse.Namespace) -> int:
    import dataclasses
    import json

    from tsid_fmu.evaluate.cost import metrics
    from tsid_fmu.evaluate.serial import SerialEvaluator
    from tsid_fmu.report.plots import fit_plot
    from tsid_fmu.study import Study, prepare

    study = Study.from_toml(args.study)
    values: dict[str, float] = {}
    interface = None  # the interface the identification chose (solver fidelity check)
    if args.result:
        path = Path(args.result)
        path = path / "result.json" if path.is_dir() else path
        try:
            saved = json.loads(path.read_text())
            values.update(saved["x"])
            interface = (saved.get("extra") or {}).get("fidelity", {}).get("interface")
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise StudyError(
                f"{path}: cannot read identified parameters ({type(exc).__name__})"
            ) from None
    for name, text in _parse_assignments(args.set, "--set").items():
        try:
            values[name] = float(text)
        except ValueError:
            raise StudyError(f"--set {name}={text}: not a number") from None
    unknown = sorted(set(values) - set(study.parameter_names))
    if unknown:
        raise StudyError(f"--set: {unknown} are not parameters of the study")
    # parameters not given keep the FMU's start values
    spec = prepare(study, None, [n for n in study.parameter_names if n in values])
    if interface is not None:
        spec = dataclasses.replace(spec, interface=interface)
    with SerialEvaluator(spec) as ev:
        simulated = ev.simulate([values], count=False)[0]
    print(
        "parameters: "
        + (", ".join(f"{k}={v:.6g}" for k, v in values.items()) or "the FMU's start values")
    )
    for e, sim in zip(spec.experiments, simulated, strict=True):
        if sim.outputs is None:
            print(f"{e.name}: simulation failed: {sim.error}")
            continue
        for out_name, m in metrics(e.time, e.measured, sim.outputs, list(e.output_names)).items():
            print(
                f"{e.name} / {out_name}: fit {m['fit_percent']:.3f} %, IAE {m['iae']:.6g}, "
                f"SSE {m['sse']:.6g}, RMSE {m['rmse']:.6g}"
            )
    plot = Path(args.plot)
    fit_plot(spec, simulated, plot, title="tsid simulate")
    print(f"plot: {plot}")
    return 0 if all(sim.error is None for sim in simulated) else 1


def _cmd_info(args: argparse.Namespace) -> int:
    from tsid_fmu.fmu import fmu_info

    print(fmu_info(args.fmu))
    return 0


def _cmd_build(args: argparse.Namespace) -> int:
    try:
        from tsid_fmu.build import main as build_main
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise StudyError(f"the FMU build is not available ({exc})") from None
    return int(build_main(list(args.build_args)) or 0)


def make_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``tsid``."""
    parser = argparse.ArgumentParser(
        prog="tsid", description="Taguchi-method identification of FMU parameters."
    )
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("identify", help="run a study file")
    p.add_argument("study", help="study file (TOML)")
    p.add_argument("--out", help="output folder (default: results/ beside the study)")
    p.add_argument("--resume", action="store_true", help="continue the study in --out")
    p.add_argument("--max-iterations", type=int, help="override the study's limit")
    p.add_argument(
        "--pause-after",
        type=int,
        metavar="N",
        help="stop after N iterations to review/edit next_levels.toml, then --resume",
    )
    p.add_argument(
        "--continue-from-run",
        type=int,
        metavar="N",
        help="with --resume: centre the next levels on run N of the last iteration",
    )
    p.add_argument(
        "--workers", type=int, metavar="N", help="worker processes (default: all cores; 1 = serial)"
    )
    p.add_argument(
        "--timeout",
        type=float,
        metavar="SECONDS",
        help="time limit per simulation; a run past it fails and the study goes on",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run simulations on this dask.distributed scheduler (needs tsid-fmu[dask])",
    )
    p.add_argument("--no-plots", action="store_true", help="skip the PNG plots")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=_cmd_identify)

    p = sub.add_parser("simulate", help="simulate one parameter set against a study's data")
    p.add_argument("study", help="study file (TOML)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE")
    p.add_argument("--result", help="use the parameters of a result folder or result.json")
    p.add_argument("--plot", default="simulate.png", help="PNG to write (default simulate.png)")
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("info", help="describe an FMU")
    p.add_argument("fmu")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("build", help="build FMUs from models/ (needs tsid-fmu[build])")
    p.add_argument("build_args", nargs=argparse.REMAINDER, help="arguments of tsid_fmu.build")
    p.set_defaults(func=_cmd_build)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status."""
    args = make_parser().parse_args(argv)
    try:
        return args.func(args)
    except TsidError as exc:
        print(f"tsid: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(
            "\ntsid: interrupted; finished iterations are kept - continue with --resume",
            file=sys.stderr,
        )
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
