"""Command line: ``tsid identify | simulate | info | init | build | screen | design``.

Every ending is one exit status (:data:`EXIT_STATUSES`) and, for an error, one line on
stderr, never a traceback: errors of the package (:class:`~tsid_fmu.errors.TsidError`,
bad input) exit with 2, an environment error (full disk, read-only folder) with 4
naming the path, an interrupted study with 130 saying how to resume, and a closed
pipe (``tsid info FMU | head``) quietly with 141. Only a bug in tsid-fmu prints a
traceback, and exits with 70, so that a script never takes a crash for a result.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tsid_fmu.cli_design import add_design_parser
from tsid_fmu.cli_exits import (
    environment,
    error,
    interrupted,
    native_output_to_stderr,
    quiet_stdout,
)
from tsid_fmu.cli_screen import add_screen_parser
from tsid_fmu.cli_values import (
    choice_value,
    iteration_count,
    not_parameters,
    parse_assignments,
    saved_result,
    timeout_seconds,
    worker_count,
)
from tsid_fmu.cli_warnings import warnings_to_log
from tsid_fmu.errors import ResourceError, StudyError, TsidError
from tsid_fmu.interrupt import (
    delivered_interrupts,
    take_startup_interrupt,
    terminated_as_interrupt,
)

__all__ = ["EXIT_STATUSES", "main"]

EXIT_STATUSES = """\
exit status:
  0    converged
  1    stopped at a limit (iterations, simulations) with a valid result
  2    bad input: a study, data or FMU file, or an output folder that holds another
       study or is in use (one line on stderr naming the file, key or folder); also
       an FMU that finishes no simulation at the start points within --timeout
  3    paused for review (--pause-after): edit next_levels.toml, then --resume
  4    environment error: disk full, folder read-only, no permission (one line
       naming the path)
  70   internal error: a bug in tsid-fmu (the traceback is printed: please report it)
  130  interrupted (Ctrl-C): finished iterations are kept, continue with --resume
  143  terminated (SIGTERM): as 130
  141  the reader of the output went away (tsid info FMU | head): ends quietly
"""


def _identify_out(args: argparse.Namespace) -> Path:
    """Return the output folder of ``tsid identify``: ``--out``, else results/ beside it."""
    return Path(args.out) if args.out else Path(args.study).with_suffix("").parent / "results"


def _warnings_folder(args: argparse.Namespace) -> Path | None:
    """Return the folder whose ``warnings.log`` holds a quiet command's warnings, or None."""
    return _identify_out(args) if args.command == "identify" else None


def _cmd_identify(args: argparse.Namespace) -> int:
    from tsid_fmu.identify import identify

    out = _identify_out(args)
    result = identify(
        args.study,
        out,
        resume=args.resume,
        max_iterations=args.max_iterations,
        pause_after=args.pause_after,
        progress=_show_progress(args.quiet, sys.stderr),
        plots=not args.no_plots,
        continue_from_run=args.continue_from_run,
        workers=args.workers,
        timeout=args.timeout,
        scheduler=args.scheduler,
    )
    code = result.status  # the exit status (tsid_fmu.result.STATUS)
    if args.json:
        import json

        summary = {**result.summary(), "exit_status": code}
        print(json.dumps(summary, indent=1, allow_nan=False))
    else:
        _print_result(result, out, verbose=args.verbose)
    return code


def _show_progress(quiet: bool, stream: Any) -> bool:
    """Return True if ``tsid identify`` shows its progress: on any stderr, unless ``-q``.

    On a terminal the progress is a live status bar and a line per iteration; written
    to a file or a pipe (a log, a CI job, a notebook cell) it is a plain line per
    iteration and stage (:class:`~tsid_fmu.report.console.ConsoleProgress`).
    """
    return not quiet


def _print_result(result: Any, out: Path, verbose: bool = False) -> None:
    """Print the text report (:meth:`IdentificationResult.text_report`), then its files."""
    print(result.text_report(verbose=verbose))
    print(f"report: {out}/report.html (text: {out}/report.md)")


def _cmd_simulate(args: argparse.Namespace) -> int:
    import dataclasses

    from tsid_fmu.evaluate.serial import SerialEvaluator
    from tsid_fmu.report.plots import fit_plot
    from tsid_fmu.study import Study, prepare
    from tsid_fmu.study.units import study_units
    from tsid_fmu.uncertainty.fidelity import chosen_cs_tolerance, chosen_interface

    study = Study.from_toml(args.study)
    values: dict[str, float] = {}
    interface = None  # the interface the identification chose (solver fidelity check)
    cs_tolerance = None  # and the FMU's Co-Simulation tolerance
    if args.result:
        saved = saved_result(Path(args.result))
        values.update(saved["params"])
        kept = (saved.get("extra") or {}).get("fidelity")  # result.json's form
        interface = chosen_interface(kept)
        cs_tolerance = chosen_cs_tolerance(kept)
    chosen = {c.name: c for c in study.choices}  # a choice as its label (model=Drag)
    for name, text in parse_assignments(args.set, "--set", last=True).items():
        if name in chosen:
            values[name] = choice_value(chosen[name], name, text)
            continue
        try:
            values[name] = float(text)
        except ValueError:
            raise StudyError(f"--set {name}={text}: not a number") from None
    names = [*study.parameter_names, *study.choice_names]  # a structure's choices too
    unknown = sorted(set(values) - set(names))
    if unknown:
        raise StudyError(not_parameters(unknown, names))
    for c in chosen.values():
        if c is study.variants and c.name not in values:
            raise StudyError(
                f"the study chooses among FMU files: say which with --set {c.name}=VARIANT "
                f"({', '.join(c.labels)})"
            )
    # parameters not given keep the FMU's start values
    spec = prepare(study, None, [n for n in names if n in values])
    if interface is not None:
        spec = dataclasses.replace(spec, interface=interface)
    if cs_tolerance is not None and spec.cs_tolerance is None:
        spec = dataclasses.replace(spec, cs_tolerance=cs_tolerance)
    with SerialEvaluator(spec) as ev:
        simulated = ev.simulate([values], count=False)[0]
    shown = [
        f"{k}={chosen[k].label_of(v) if k in chosen else f'{v:.6g}'}" for k, v in values.items()
    ]
    print("parameters: " + (", ".join(shown) or "the FMU's start values"))
    for e, sim in zip(spec.experiments, simulated, strict=True):
        if sim.outputs is None:
            print(f"{e.name}: simulation failed: {sim.error}")
            continue
        for out_name, m in e.fit_metrics(sim.outputs).items():  # the scored windows
            print(
                f"{e.name} / {out_name}: fit {m['fit_percent']:.3f} %, IAE {m['iae']:.6g}, "
                f"SSE {m['sse']:.6g}, RMSE {m['rmse']:.6g}"
            )
    plot = Path(args.plot)
    fit_plot(spec, simulated, plot, title="tsid simulate", units=study_units(study))
    print(f"plot: {plot}")
    if args.csv:
        for path in _write_csv(Path(args.csv), spec, simulated):
            print(f"simulated outputs: {path}")
    failed = [sim.experiment for sim in simulated if sim.error is not None]
    print(f"simulation failed: {', '.join(failed)}" if failed else "simulated every experiment")
    return 1 if failed else 0


def _write_csv(path: Path, spec: Any, simulated: Sequence[Any]) -> list[Path]:
    """Write time and simulated outputs, one CSV per experiment (suffixed if several)."""
    import pandas as pd

    written = []
    for e, sim in zip(spec.experiments, simulated, strict=True):
        if sim.outputs is None:
            continue
        target = path
        if len(spec.experiments) > 1:
            slug = "".join(c if c.isalnum() else "_" for c in e.name)
            target = path.with_name(f"{path.stem}_{slug}{path.suffix or '.csv'}")
        frame = pd.DataFrame(sim.outputs, columns=list(e.output_names))
        frame.insert(0, "time", e.time)
        target.parent.mkdir(parents=True, exist_ok=True)
        frame.to_csv(target, index=False)
        written.append(target)
    return written


def _cmd_info(args: argparse.Namespace) -> int:
    from tsid_fmu.evaluate.conformance import info_line
    from tsid_fmu.fmu import fmu_info

    print(fmu_info(args.fmu))
    print(info_line(Path(args.fmu), args.probe))
    if args.all:
        print(_all_variables(Path(args.fmu)))
    return 0


def _all_variables(path: Path) -> str:
    """Every variable of an FMU with its causality (locals included), for ``info --all``."""
    from tsid_fmu.fmu.info import printable, read_fmu_description, type_text
    from tsid_fmu.fmu.variables import variable_info

    infos = [variable_info(v) for v in read_fmu_description(path).modelVariables]
    width = max((len(v.name) for v in infos), default=4)
    lines = ["", f"All variables ({len(infos)})"]
    lines.append(f"  {'name':<{width}}  {'causality':<20} {'variability':<11} type     unit")
    for v in infos:
        lines.append(
            f"  {v.name:<{width}}  {v.causality or '-':<20} {v.variability or '-':<11} "
            f"{type_text(v):<8} {v.unit or ''}".rstrip()
        )
    return "\n".join(printable(line) for line in lines)


def _cmd_init(args: argparse.Namespace) -> int:
    derived = parse_assignments(args.derived, "--derived")
    target = Path(args.output)
    if target.is_dir():
        raise StudyError(f"-o {target}: is a folder; give the study file to write")
    if target.exists() and not args.force:
        raise StudyError(f"-o {target}: the file exists; give --force to overwrite it")
    from tsid_fmu.scaffold import init_and_screen
    from tsid_fmu.scaffold_screen import console_progress

    _, found = init_and_screen(
        args.fmu,
        args.data,
        args.output,
        derived=derived,
        screen=not args.no_screen,
        workers=args.workers,
        progress=None if args.quiet else console_progress(),
    )
    print(f"study written: {args.output}" + (f" ({found.summary()})" if found else ""))
    print(f"run it: tsid identify {args.output} --out DIR")
    return 0


def _cmd_build(args: argparse.Namespace) -> int:
    try:
        from tsid_fmu.build import main as build_main
    except ImportError as exc:  # pragma: no cover - depends on the install
        raise StudyError(f"the FMU build is not available ({exc})") from None
    argv = list(args.models)
    if args.out:
        argv += ["--out", args.out]
    if args.models_dir:
        argv += ["--models-dir", args.models_dir]
    if args.from_result:
        argv += ["--from-result", args.from_result]
    else:
        argv += ["--fmi-version", args.fmi_version]
    return int(build_main(argv) or 0)


def _identify_parser(sub: Any) -> None:
    p = sub.add_parser("identify", help="run a study file")
    p.add_argument("study", help="study file (TOML)")
    p.add_argument("--out", help="output folder (default: results/ beside the study)")
    p.add_argument("--resume", action="store_true", help="continue the study in --out")
    p.add_argument(
        "--max-iterations", type=iteration_count, metavar="N", help="override the study's limit"
    )
    p.add_argument(
        "--pause-after",
        type=iteration_count,
        metavar="N",
        help="stop after N iterations of this run (with --resume: N more) to review/edit "
        "next_levels.toml, then --resume",
    )
    p.add_argument(
        "--continue-from-run",
        type=iteration_count,
        metavar="N",
        help="with --resume: centre the next levels on run N of the last iteration",
    )
    p.add_argument(
        "--workers",
        type=worker_count,
        metavar="N",
        help="worker processes (default: all cores; 1 = one worker process, or this process "
        "with --timeout 0)",
    )
    p.add_argument(
        "--timeout",
        type=timeout_seconds,
        metavar="SECONDS",
        help="time limit per simulation, checks included (0: none; default: automatic, from "
        "the first runs); a run past it fails and the study goes on",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run simulations on this dask.distributed scheduler (needs tsid-fmu[dask])",
    )
    p.add_argument(
        "--no-plots", action="store_true", help="skip the figures (report.html has tables only)"
    )
    p.add_argument(
        "-q",
        "--quiet",
        action="store_true",
        help="no progress on stderr (a live bar on a terminal, a line per iteration and "
        "stage elsewhere), and no library warnings: they go to OUT/warnings.log",
    )
    p.add_argument(
        "-v",
        "--verbose",
        action="store_true",
        help="after the verdict, how the study got there (each stage's reasons) and the "
        "fit statistics",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print the result as JSON on stdout instead of the table (progress stays on "
        "stderr); its layout: tsid_fmu/schemas/result-summary.schema.json",
    )
    p.set_defaults(func=_cmd_identify)


def _init_parser(sub: Any) -> None:
    p = sub.add_parser(
        "init",
        help="write a commented study file from an FMU and a data file",
        description="Write a study that runs as written: the FMU's inputs and outputs "
        "matched to the data's columns by name (case-insensitively), every real parameter "
        "with five log-spaced levels over one decade around its start value.",
    )
    p.add_argument("fmu", help="the .fmu file")
    p.add_argument("data", help="measured data (CSV; a column 'time' or the first column)")
    p.add_argument("-o", "--output", default="study.toml", help="study file to write")
    p.add_argument("--force", action="store_true", help="overwrite the study file if it exists")
    p.add_argument(
        "--derived",
        action="append",
        default=[],
        metavar="NAME=EXPRESSION",
        help="a channel computed from the columns, e.g. 'F_o=F_of - F_or' (repeatable)",
    )
    p.add_argument(
        "--no-screen",
        action="store_true",
        help="free every candidate without screening it (by default 2p+1 simulations at the "
        "start values hold what the data cannot see, or see only in combination)",
    )
    p.add_argument("--workers", type=int, default=None, help="worker processes of the screening")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=_cmd_init)


def _other_parsers(sub: Any) -> None:
    p = sub.add_parser(
        "simulate",
        help="simulate one parameter set against a study's data",
        description="Simulate the study's FMU on the measured inputs of its identification "
        "experiments. Parameters keep the FMU's start values (or the study's start_values) "
        "unless --result or --set gives them.",
    )
    p.add_argument("study", help="study file (TOML)")
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="value of one study parameter (repeatable); applied after --result; split at "
        "the last '=' (a name may hold one); a name in double quotes, TOML's escapes "
        "allowed, keeps spaces at its ends",
    )
    p.add_argument("--result", help="use the parameters of a result folder or result.json")
    p.add_argument("--plot", default="simulate.png", help="PNG to write (default simulate.png)")
    p.add_argument(
        "--csv",
        metavar="FILE",
        help="write time and the simulated outputs to FILE (FILE_<experiment>.csv if several)",
    )
    p.set_defaults(func=_cmd_simulate)

    p = sub.add_parser("info", help="describe an FMU")
    p.add_argument("fmu", help="the .fmu file")
    p.add_argument(
        "--all", action="store_true", help="also list every variable (locals too) with causality"
    )
    p.add_argument(
        "--probe",
        action="store_true",
        help="probe reset and determinism at the FMU's defaults (an FMU without inputs)",
    )
    p.set_defaults(func=_cmd_info)

    _init_parser(sub)

    p = sub.add_parser(
        "build",
        help="build FMUs from models/, or with --from-result DIR rebuild a study's FMU with "
        "its identified values (needs tsid-fmu[build])",
    )
    p.add_argument("models", nargs="*", metavar="MODEL", help="models to build (default: all)")
    p.add_argument("--out", help="output folder (default: fmus/ beside models/)")
    p.add_argument("--models-dir", help="Modelica folder (default: ./models)")
    p.add_argument(
        "--fmi-version", choices=["2", "3", "all"], default="all", help="FMI version(s) to write"
    )
    p.add_argument(
        "--from-result",
        metavar="DIR",
        help="rebuild the FMU of the study whose output folder is DIR (its model.ssp) with the "
        "identified values as start values: DIR/<Model>_identified.fmu (or in --out)",
    )
    p.set_defaults(func=_cmd_build)


def make_parser() -> argparse.ArgumentParser:
    """Return the argument parser of ``tsid``."""
    from tsid_fmu import __version__

    parser = argparse.ArgumentParser(
        prog="tsid",
        description="Taguchi-method identification of FMU parameters.",
        epilog=EXIT_STATUSES,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--version", action="version", version=f"tsid {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    _identify_parser(sub)
    _other_parsers(sub)
    add_screen_parser(sub)  # cli_screen.py
    add_design_parser(sub)  # cli_design.py
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; return the exit status (see :data:`EXIT_STATUSES`)."""
    held = take_startup_interrupt()  # Ctrl-C or SIGTERM while the package was imported
    if held is not None:
        return interrupted(held == signal.SIGTERM, argv)
    terminated: list[int] = []
    try:
        # Ctrl-C and SIGTERM neither lost nor raised inside an import
        with terminated_as_interrupt() as terminated, delivered_interrupts():
            args = make_parser().parse_args(argv)
            quiet = getattr(args, "quiet", False)  # -q: warnings to the log, not stderr
            kept = warnings_to_log(_warnings_folder(args)) if quiet else contextlib.nullcontext()
            with native_output_to_stderr(), kept:
                status = int(args.func(args))
        sys.stdout.flush()  # a closed pipe shows here, not at exit
        return status
    except ResourceError as exc:  # a TsidError, but the machine's fault, not the input's
        return error(str(exc), 4)
    except TsidError as exc:
        return error(str(exc), 2)
    except RecursionError:
        return error("an input file is nested too deeply to read", 2)
    except BrokenPipeError:
        quiet_stdout()
        return 141
    except OSError as exc:
        return error(environment(exc), 4)
    except MemoryError:
        return error("out of memory", 4)
    except KeyboardInterrupt:
        return interrupted(bool(terminated), argv)
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
