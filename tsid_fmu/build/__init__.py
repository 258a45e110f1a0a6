"""Build FMI 2.0 FMUs (Co-Simulation and Model Exchange) from Modelica sources.

Modelica is the single source of a plant model. The build

1. parses and flattens the model with pymoca (:mod:`.modelica`),
2. sorts and solves the equations for the derivatives and outputs and generates C code
   for them with CasADi (:mod:`.codegen`),
3. writes ``modelDescription.xml`` from the declarations (:mod:`.model_description`),
4. compiles the generated model part together with the hand-written, generic FMI 2.0
   wrapper in ``tsid_fmu/build/c/`` and packs the FMU, sources included
   (:mod:`.packaging`).

Building needs a C compiler and the ``build`` extra (``pip install tsid-fmu[build]``);
using a built FMU needs neither.

Public API
----------
``build_fmu(model_file, model_name, out_path=None, *, package_dir=None, step_size=None)``
    Build one FMU and return its path.
``build_all(models_dir=None, out_dir=None, names=None)``
    Build every model (or the named ones) of a Modelica package directory.
``main(argv=None)``
    Command line: ``python -m tsid_fmu.build [--all | MODEL ...] [--out DIR]``.
"""

from __future__ import annotations

import argparse
import hashlib
import re
import shutil
import sys
import tempfile
import uuid
from pathlib import Path

from tsid_fmu.errors import BuildError

__all__ = [
    "DEFAULT_STEP_SIZE",
    "build_all",
    "build_fmu",
    "default_models_dir",
    "find_models",
    "main",
]

#: Default of the Co-Simulation parameter ``fixedStepSize`` [s] when the model does not
#: give one with the vendor annotation ``annotation(__tsid_fmu(fixedStepSize = ...))``.
DEFAULT_STEP_SIZE = 1e-4

_STEP_RE = re.compile(r"__tsid_fmu\s*\(\s*fixedStepSize\s*=\s*([-+0-9.eE]+)\s*\)")
_MODEL_RE = re.compile(r"^\s*(?:partial\s+)?model\s+(\w+)", re.M)


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("tsid-fmu")
    except Exception:  # pragma: no cover - not installed
        return "0"


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


def build_fmu(
    model_file: str | Path,
    model_name: str,
    out_path: str | Path | None = None,
    *,
    package_dir: str | Path | None = None,
    step_size: float | None = None,
) -> Path:
    """Build an FMI 2.0 FMU (Co-Simulation and Model Exchange) from a Modelica model.

    Parameters
    ----------
    model_file : str or Path
        The ``.mo`` file holding the model.
    model_name : str
        Qualified (``"TSID.LSEA_SISO"``) or short (``"LSEA_SISO"``) name of the model. The
        last component is the FMI model identifier and must be a C identifier.
    out_path : str or Path, optional
        The ``.fmu`` file to write, or an existing directory to write
        ``<Model>.fmu`` into. Default: ``fmus/<Model>.fmu`` in the working directory.
    package_dir : str or Path, optional
        Directory whose other ``.mo`` files are parsed too (models that use other classes
        of their package).
    step_size : float, optional
        Default of the parameter ``fixedStepSize`` (internal RK4 step of Co-Simulation,
        in s). Default: the model's ``annotation(__tsid_fmu(fixedStepSize = ...))``, else
        :data:`DEFAULT_STEP_SIZE`.

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
    from .codegen import causalize, generate_c
    from .model_description import FIXED_STEP_NAME, model_description_xml
    from .modelica import flatten_model
    from .packaging import C_DIR, WRAPPER_FILES, compile_binary, fmi_platform, zip_fmu

    model_file = Path(model_file)
    model = flatten_model(model_file, model_name, package_dir)
    ident = model.short_name
    if not re.fullmatch(r"[A-Za-z_]\w*", ident):
        raise BuildError(f"{model_file}: model name {ident!r} is not a valid C identifier")
    names = {
        v.name
        for v in model.states + model.inputs + model.outputs + model.parameters + model.locals
    }
    if FIXED_STEP_NAME in names:
        raise BuildError(
            f"{model_file}: model {model.name} declares '{FIXED_STEP_NAME}', "
            "a name reserved for the FMU's internal step parameter"
        )
    text = model_file.read_text(encoding="utf-8")
    if step_size is None:
        m = _STEP_RE.search(text)
        step_size = float(m.group(1)) if m else DEFAULT_STEP_SIZE
    if not step_size > 0:
        raise BuildError(f"{model_file}: fixedStepSize must be > 0, got {step_size}")

    if out_path is None:
        out = Path.cwd() / "fmus" / f"{ident}.fmu"
    else:
        out = Path(out_path)
        if out.is_dir():
            out = out / f"{ident}.fmu"

    causal = causalize(model)
    wrapper = "".join((C_DIR / f).read_text() for f in WRAPPER_FILES)
    digest = hashlib.sha256(
        "\0".join([model.name, text, repr(step_size), _version(), wrapper]).encode()
    ).hexdigest()
    guid = "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, "tsid-fmu:" + digest)) + "}"

    plat, _ = fmi_platform()
    with tempfile.TemporaryDirectory(prefix=f"tsid_build_{ident}_") as tmp:
        root = Path(tmp) / "fmu"
        src = root / "sources"
        src.mkdir(parents=True)
        for f in WRAPPER_FILES:
            shutil.copy2(C_DIR / f, src / f)
        generated = generate_c(model, causal, src, guid=guid, step_size=step_size)
        source_files = ["fmi2Functions.c", *generated]
        xml = model_description_xml(
            model,
            causal,
            guid=guid,
            step_size=step_size,
            source_files=source_files,
            generation_tool=f"tsid-fmu {_version()}",
        )
        (root / "modelDescription.xml").write_text(xml, encoding="utf-8")
        doc = root / "documentation"
        doc.mkdir()
        (doc / "index.html").write_text(
            f"<html><head><title>{model.name}</title></head><body>\n<h1>{model.name}</h1>\n"
            f"<p>{model.description}</p>\n{_strip_html(model.info_html)}\n</body></html>\n",
            encoding="utf-8",
        )
        res = root / "resources"
        res.mkdir()
        shutil.copy2(model_file, res / model_file.name)
        compile_binary(src, ident, root / "binaries" / plat, generated)
        zip_fmu(root, out)
    return out


def _strip_html(info: str) -> str:
    """Return the body of a Modelica ``info`` string (without ``<html>`` tags)."""
    return re.sub(r"</?html>", "", info).strip()


def build_all(
    models_dir: str | Path | None = None,
    out_dir: str | Path | None = None,
    names: list[str] | None = None,
) -> list[Path]:
    """Build every model of a Modelica directory (or the named ones) into ``out_dir``.

    Parameters
    ----------
    models_dir : str or Path, optional
        Directory with the Modelica package(s); default :func:`default_models_dir`.
    out_dir : str or Path, optional
        Output directory; default ``fmus/`` next to ``models_dir``.
    names : list of str, optional
        Short model names to build; default all models found.

    Returns
    -------
    list of Path
        The FMUs written.

    Raises
    ------
    BuildError
        If a named model does not exist or a build fails.
    """
    mdir = Path(models_dir) if models_dir is not None else default_models_dir()
    odir = Path(out_dir) if out_dir is not None else mdir.resolve().parent / "fmus"
    odir.mkdir(parents=True, exist_ok=True)
    models = find_models(mdir)
    if not models:
        raise BuildError(f"no Modelica models found in {mdir}")
    wanted = names or list(models)
    out = []
    for name in wanted:
        short = name.rsplit(".", 1)[-1]
        if short not in models:
            raise BuildError(f"model {name!r} not found in {mdir} (available: {', '.join(models)})")
        out.append(
            build_fmu(models[short], name, odir / f"{short}.fmu", package_dir=models[short].parent)
        )
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
        description="Build FMI 2.0 FMUs (CS + ME) from the Modelica models in models/.",
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
    args = parser.parse_args(argv)
    if args.all and args.models:
        parser.error("give either --all or model names, not both")
    try:
        paths = build_all(args.models_dir, args.out, args.models or None)
    except BuildError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    for p in paths:
        print(p)
    return 0
