"""Build FMI 2.0 and FMI 3.0 FMUs (Co-Simulation and Model Exchange) from Modelica.

Modelica is the single source of a plant model. The build

1. parses and flattens the model with pymoca (:mod:`.modelica`, :mod:`.expressions`),
2. sorts and solves the equations for the derivatives and outputs (:mod:`.causalize`),
   once with the relations evaluated live (Co-Simulation) and once with every relation
   a discrete state (Model Exchange: event indicators, events), and generates C code
   for both with CasADi (:mod:`.codegen`),
3. writes ``modelDescription.xml`` from the declarations (:mod:`.model_description`,
   :mod:`.model_description3`),
4. compiles the generated model part together with the hand-written, generic wrapper
   in ``tsid_fmu/build/c/`` (a shared core ``tsid_core.c`` under ``fmi2Functions.c`` or
   ``fmi3Functions.c``) and packs the FMU, sources included (:mod:`.packaging`,
   :mod:`.assemble`).

Building needs a C compiler and the ``build`` extra (``pip install tsid-fmu[build]``);
using a built FMU needs neither.

Public API
----------
``build_fmu(model_file, model_name, out_path=None, *, package_dir=None, step_size=None,
fmi_version=2)``
    Build one FMU and return its path.
``build_all(models_dir=None, out_dir=None, names=None, fmi_versions=(2, 3))``
    Build every model (or the named ones) of a Modelica package directory: FMI 2.0 into
    ``<out>/<Model>.fmu``, FMI 3.0 into ``<out>/fmi3/<Model>.fmu``.
``main(argv=None)``
    Command line: ``python -m tsid_fmu.build [--all | MODEL ...] [--out DIR]
    [--fmi-version {2,3,all}]``.
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from tsid_fmu.errors import BuildError

from .assemble import DEFAULT_STEP_SIZE
from .identified import build_from_result

__all__ = [
    "DEFAULT_STEP_SIZE",
    "FMI_VERSIONS",
    "build_all",
    "build_fmu",
    "build_from_result",
    "default_models_dir",
    "find_models",
    "main",
    "output_path",
]

#: The FMI versions the build writes.
FMI_VERSIONS = (2, 3)

_MODEL_RE = re.compile(r"^\s*(?:partial\s+)?model\s+(\w+)", re.M)


def default_models_dir() -> Path:
    """Return the ``models/`` directory: in the working directory, else in the repository.

    Returns
    -------
    Path
        ``./models`` if it exists, otherwise ``models/`` next to the ``tsid_fmu`` package.
    """
    cwd = Path.cwd() / "models"
    if cwd.is_dir():
        return cwd
    return Path(__file__).resolve().parents[2] / "models"


def find_models(models_dir: str | Path) -> dict[str, Path]:
    """Find the (non-partial) models of a Modelica directory tree.

    Parameters
    ----------
    models_dir : str or Path
        Directory to search for ``*.mo`` files.

    Returns
    -------
    dict
        Short model name -> file, sorted by name.
    """
    found: dict[str, Path] = {}
    for mo in sorted(Path(models_dir).rglob("*.mo")):
        text = mo.read_text(encoding="utf-8")
        for m in _MODEL_RE.finditer(text):
            if "partial" in m.group(0):
                continue
            found[m.group(1)] = mo
    return dict(sorted(found.items()))


def output_path(out_dir: str | Path, model: str, fmi_version: int) -> Path:
    """Where :func:`build_all` writes a model's FMU of an FMI version.

    Parameters
    ----------
    out_dir : str or Path
        The output directory (``fmus/``).
    model : str
        Short model name.
    fmi_version : int
        2 (``<out_dir>/<model>.fmu``) or 3 (``<out_dir>/fmi3/<model>.fmu``).

    Returns
    -------
    Path
        The FMU path.
    """
    out_dir = Path(out_dir)
    return out_dir / f"{model}.fmu" if fmi_version == 2 else out_dir / "fmi3" / f"{model}.fmu"


def build_fmu(
    model_file: str | Path,
    model_name: str,
    out_path: str | Path | None = None,
    *,
    package_dir: str | Path | None = None,
    step_size: float | None = None,
    fmi_version: int = 2,
    start_values: dict[str, float] | None = None,
) -> Path:
    """Build an FMU (Co-Simulation and Model Exchange) from a Modelica model.

    Parameters
    ----------
    model_file : str or Path
        The ``.mo`` file holding the model.
    model_name : str
        Qualified (``"TSID.LSEA_SISO"``) or short (``"LSEA_SISO"``) name of the model. The
        last component is the FMI model identifier and must be a C identifier.
    out_path : str or Path, optional
        The ``.fmu`` file to write, or an existing directory to write
        ``<Model>.fmu`` into. Default: ``fmus/<Model>.fmu`` (FMI 2.0) or
        ``fmus/fmi3/<Model>.fmu`` (FMI 3.0) in the working directory.
    package_dir : str or Path, optional
        Directory whose other ``.mo`` files are parsed too (models that use other classes
        of their package).
    step_size : float, optional
        Default of the parameter ``fixedStepSize`` (internal RK4 step of Co-Simulation,
        in s). Default: the model's ``annotation(__tsid_fmu(fixedStepSize = ...))``, else
        :data:`DEFAULT_STEP_SIZE`.
    fmi_version : int, optional
        2 (default) or 3.
    start_values : dict of str to float, optional
        Values that replace the model's parameter values and state start values
        (e.g. identified ones); they become part of the GUID.

    Returns
    -------
    Path
        The written FMU.

    Raises
    ------
    BuildError
        If parsing, flattening, code generation or compilation fails, or pymoca/casadi
        are missing. The message names the file, model, equation or compiler command.
    """
    from .assemble import prepare, write_fmu

    prep = prepare(model_file, model_name, package_dir, step_size, start_values)
    ident = prep.model.short_name
    if out_path is None:
        out = output_path(Path.cwd() / "fmus", ident, fmi_version)
    else:
        out = Path(out_path)
        if out.is_dir():
            out = out / f"{ident}.fmu"
    return write_fmu(prep, out, fmi_version)


def build_all(
    models_dir: str | Path | None = None,
    out_dir: str | Path | None = None,
    names: list[str] | None = None,
    fmi_versions: tuple[int, ...] = FMI_VERSIONS,
) -> list[Path]:
    """Build every model of a Modelica directory (or the named ones) into ``out_dir``.

    Parameters
    ----------
    models_dir : str or Path, optional
        Directory with the Modelica package(s); default :func:`default_models_dir`.
    out_dir : str or Path, optional
        Output directory; default ``fmus/`` next to ``models_dir``. See
        :func:`output_path` for the file of each version.
    names : list of str, optional
        Short model names to build; default all models found.
    fmi_versions : tuple of int, optional
        FMI versions to write (default both, 2 and 3).

    Returns
    -------
    list of Path
        The FMUs written.

    Raises
    ------
    BuildError
        If a named model does not exist or a build fails.
    """
    from .assemble import prepare, write_fmu

    mdir = Path(models_dir) if models_dir is not None else default_models_dir()
    odir = Path(out_dir) if out_dir is not None else mdir.resolve().parent / "fmus"
    odir.mkdir(parents=True, exist_ok=True)
    models = find_models(mdir)
    if not models:
        raise BuildError(f"no Modelica models found in {mdir}")
    wanted = names or list(models)
    for name in wanted:
        short = name.rsplit(".", 1)[-1]
        if short not in models:
            raise BuildError(f"model {name!r} not found in {mdir} (available: {', '.join(models)})")
    out = []
    for name in wanted:
        short = name.rsplit(".", 1)[-1]
        prep = prepare(models[short], name, models[short].parent)
        for version in fmi_versions:
            out.append(write_fmu(prep, output_path(odir, short, version), version))
    return out


def main(argv: list[str] | None = None) -> int:
    """Command line ``python -m tsid_fmu.build [--all | MODEL ...] [--out DIR]``.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit code: 0 on success, 1 if a build failed, 2 on a usage error.
    """
    parser = argparse.ArgumentParser(
        prog="python -m tsid_fmu.build",
        description="Build FMI 2.0 and 3.0 FMUs (CS + ME) from the Modelica models in models/.",
    )
    parser.add_argument(
        "models", nargs="*", metavar="MODEL", help="model names to build (default: all)"
    )
    parser.add_argument("--all", action="store_true", help="build every model (default)")
    parser.add_argument(
        "--models-dir", type=Path, default=None, help="Modelica directory (default: ./models)"
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="output directory (default: fmus/ next to models/)"
    )
    parser.add_argument(
        "--from-result",
        type=Path,
        metavar="DIR",
        help="rebuild the FMU of the study whose output folder is DIR with the identified "
        "values as start values and a new GUID: DIR/<Model>_identified.fmu (or in --out)",
    )
    parser.add_argument(
        "--fmi-version",
        choices=["2", "3", "all"],
        default="all",
        help="FMI version(s) to write: 2 -> OUT/<Model>.fmu, 3 -> OUT/fmi3/<Model>.fmu "
        "(default: all)",
    )
    args = parser.parse_args(argv)
    if args.all and args.models:
        parser.error("give either --all or model names, not both")
    if args.from_result and (args.all or args.models or args.fmi_version != "all"):
        parser.error("--from-result rebuilds the study's own FMU: no models or --fmi-version")
    versions = FMI_VERSIONS if args.fmi_version == "all" else (int(args.fmi_version),)
    try:
        if args.from_result:
            paths = [build_from_result(args.from_result, args.out)]
        else:
            paths = build_all(args.models_dir, args.out, args.models or None, versions)
    except BuildError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    for p in paths:
        print(p)
    return 0
