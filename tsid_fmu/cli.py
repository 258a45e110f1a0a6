"""Command line: ``tsid identify | simulate | info | build``.

Every ending is one exit status (:data:`EXIT_STATUSES`) and, for an error, one line on
stderr, never a traceback: errors of the package (:class:`~tsid_fmu.errors.TsidError`,
bad input) exit with 2, an environment error (full disk, read-only folder) with 4
naming the path, an interrupted study with 130 saying how to resume, and a closed
pipe (``tsid info FMU | head``) quietly with 141. Only a bug in tsid-fmu prints a
traceback, and exits with 70, so that a script never takes a crash for a result.
"""

from __future__ import annotations

import argparse
import errno
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from tsid_fmu.errors import StudyError, TsidError

__all__ = ["EXIT_STATUSES", "main"]

EXIT_STATUSES = """\
exit status:
  0    converged
  1    stopped at a limit (iterations, simulations) with a valid result
  2    bad input: a study, data or FMU file, or an output folder that holds another
       study or is in use (one line on stderr naming the file, key or folder)
  3    paused for review (--pause-after): edit next_levels.toml, then --resume
  4    environment error: disk full, folder read-only, no permission (one line
       naming the path)
  70   internal error: a bug in tsid-fmu (the traceback is printed: please report it)
  130  interrupted (Ctrl-C): finished iterations are kept, continue with --resume
  141  the reader of the output went away (tsid info FMU | head): ends quietly
"""


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
        prog="tsid",
        description="Taguchi-method identification of FMU parameters.",
        epilog=EXIT_STATUSES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
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

    p = sub.add_parser(
        "build",
        help="build FMUs from models/, or with --from-result DIR rebuild a study's FMU with "
        "its identified values (needs tsid-fmu[build])",
    )
    p.add_argument("build_args", nargs=argparse.REMAINDER, help="arguments of tsid_fmu.build")
    p.set_defaults(func=_cmd_build)
    return parser


def _environment(exc: OSError) -> str:
    """One line for an environment error, naming the path."""
    reason = exc.strerror or type(exc).__name__
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        reason += " (the disk is full)"
    elif exc.errno == errno.EROFS:
        reason += " (the folder is on a read-only file system)"
    where = exc.filename if exc.filename is not None else "(path not known)"
    return f"cannot write or read {os.fsdecode(where)!s}: {reason}"


def _quiet_stdout() -> None:
    """After a broken pipe: send what is left of stdout nowhere (no second error)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # pragma: no cover - stdout without a descriptor
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (see :data:`EXIT_STATUSES`)."""
    parser = make_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # options of tsid_fmu.build before its first positional argument
        if args.command != "build":
            parser.error(f"unrecognized arguments: {' '.join(extra)}")
        args.build_args = [*extra, *args.build_args]
    try:
        status = int(args.func(args))
        sys.stdout.flush()  # a closed pipe shows here, not at exit
        return status
    except TsidError as exc:
        print(f"tsid: error: {exc}", file=sys.stderr)
        return 2
    except RecursionError:
        print("tsid: error: an input file is nested too deeply to read", file=sys.stderr)
        return 2
    except BrokenPipeError:
        _quiet_stdout()
        return 141
    except OSError as exc:
        print(f"tsid: error: {_environment(exc)}", file=sys.stderr)
        return 4
    except MemoryError:
        print("tsid: error: out of memory", file=sys.stderr)
        return 4
    except KeyboardInterrupt:
        print(
            "\ntsid: interrupted; finished iterations are kept - continue with --resume",
            file=sys.stderr,
        )
        return 130
    except Exception:  # a bug: the traceback is what a report of it needs
        import traceback

        traceback.print_exc()
        print(
            "tsid: internal error: this is a bug in tsid-fmu; please report it with the "
            "command you ran and the traceback above",
            file=sys.stderr,
        )
        return 70


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
