"""Assemble FMI 2.0 and FMI 3.0 FMUs from one flattened, causalized model.

:func:`prepare` does the version-independent part once (parse, flatten, causalize in
the live and the frozen form); :func:`write_fmu` writes the sources, the model
description and the documentation of one FMI version, compiles and packs the FMU.
"""

from __future__ import annotations

import hashlib
import math
import re
import shutil
import tempfile
import uuid
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from tsid_fmu.errors import BuildError

from .causalize import Causalized
from .modelica import FlatModel

__all__ = ["DEFAULT_STEP_SIZE", "Prepared", "prepare", "write_fmu"]

#: Default of the Co-Simulation parameter ``fixedStepSize`` [s] when the model does not
#: give one with the vendor annotation ``annotation(__tsid_fmu(fixedStepSize = ...))``.
DEFAULT_STEP_SIZE = 1e-4

_STEP_RE = re.compile(r"__tsid_fmu\s*\(\s*fixedStepSize\s*=\s*([-+0-9.eE]+)\s*\)")


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("tsid-fmu")
    except Exception:  # pragma: no cover - not installed
        return "0"


@dataclass
class Prepared:
    """A model ready to be written as an FMU of either FMI version.

    Attributes
    ----------
    model : FlatModel
        The flattened model.
    model_file : Path
        Its Modelica source.
    text : str
        The source text (part of the GUID).
    step_size : float
        Default of ``fixedStepSize``.
    causal : Causalized
        Live form (Co-Simulation, model structure).
    causal_me : Causalized or None
        Frozen form (Model Exchange); ``None`` if the model has no relations.
    overrides : dict of str to float
        Start values that replace the model's (part of the GUID).
    """

    model: FlatModel
    model_file: Path
    text: str
    step_size: float
    causal: Causalized
    causal_me: Causalized | None
    overrides: dict[str, float] = field(default_factory=dict)


def _override(model: FlatModel, model_file: Path, values: Mapping[str, float]) -> dict[str, float]:
    """Replace parameter values and state start values of ``model`` in place.

    A state whose initial value is an expression of parameters follows the new
    parameter values; a value given for the state itself replaces that expression.
    """
    settable = {v.name: v for v in model.parameters + model.states}
    done = {}
    for name, value in values.items():
        if name not in settable:
            raise BuildError(
                f"{model_file}: model {model.name} has no parameter or state named {name!r} "
                f"(start values can be given for: {', '.join(sorted(settable))})"
            )
        value = float(value)
        if not math.isfinite(value):
            raise BuildError(f"{model_file}: start value of {name!r} must be finite, got {value}")
        settable[name].start = done[name] = value
        if settable[name].kind == "state":
            settable[name].init = None
    model.update_initial_starts()
    return done


def prepare(
    model_file: str | Path,
    model_name: str,
    package_dir: str | Path | None = None,
    step_size: float | None = None,
    start_values: Mapping[str, float] | None = None,
) -> Prepared:
    """Parse, flatten and causalize a model: the first half of :func:`~tsid_fmu.build.build_fmu`.

    Parameters
    ----------
    model_file, model_name, package_dir, step_size, start_values
        As for :func:`~tsid_fmu.build.build_fmu`.

    Returns
    -------
    Prepared
        The model in both forms.

    Raises
    ------
    BuildError
        If the model cannot be flattened or causalized, uses a reserved name, its
        name is no C identifier, or a start value names no parameter or state.
    """
    from .causalize import causalize
    from .model_description import FIXED_STEP_NAME
    from .model_description3 import EVENT_INDICATOR_PREFIX
    from .modelica import flatten_model

    model_file = Path(model_file)
    model = flatten_model(model_file, model_name, package_dir)
    ident = model.short_name
    if not re.fullmatch(r"[A-Za-z_]\w*", ident):
        raise BuildError(f"{model_file}: model name {ident!r} is not a valid C identifier")
    for v in model.states + model.inputs + model.outputs + model.parameters + model.locals:
        if v.name == FIXED_STEP_NAME:
            raise BuildError(
                f"{model_file}: model {model.name} declares '{FIXED_STEP_NAME}', "
                "a name reserved for the FMU's internal step parameter"
            )
        if v.name.startswith(EVENT_INDICATOR_PREFIX):
            raise BuildError(
                f"{model_file}: model {model.name} declares '{v.name}'; names starting "
                f"with '{EVENT_INDICATOR_PREFIX}' are reserved for event indicators"
            )
    text = model_file.read_text(encoding="utf-8")
    if step_size is None:
        m = _STEP_RE.search(text)
        step_size = float(m.group(1)) if m else DEFAULT_STEP_SIZE
    if not step_size > 0:
        raise BuildError(f"{model_file}: fixedStepSize must be > 0, got {step_size}")
    overrides = _override(model, model_file, start_values or {})
    causal = causalize(model)
    causal_me = causalize(model, frozen=True) if model.relations else None
    return Prepared(model, model_file, text, step_size, causal, causal_me, overrides)


def _token(prep: Prepared, fmi_version: int) -> str:
    """GUID / instantiation token: a hash of everything the FMU is made of."""
    from .packaging import C_DIR, wrapper_files

    wrapper = "".join((C_DIR / f).read_text() for f in wrapper_files(fmi_version))
    parts = [prep.model.name, prep.text, repr(prep.step_size), _version(), wrapper]
    if fmi_version != 2:
        parts.append(f"fmi{fmi_version}")
    if prep.overrides:  # another parameterisation is another model: a new GUID
        parts.append(repr(sorted(prep.overrides.items())))
    digest = hashlib.sha256("\0".join(parts).encode()).hexdigest()
    return "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, "tsid-fmu:" + digest)) + "}"


def _strip_html(info: str) -> str:
    """Return the body of a Modelica ``info`` string (without ``<html>`` tags)."""
    return re.sub(r"</?html>", "", info).strip()


def _model_description(prep: Prepared, token: str, fmi_version: int, sources: list[str]) -> str:
    from .model_description import model_description_xml
    from .model_description3 import model_description3_xml

    relations = prep.causal_me.relations if prep.causal_me is not None else []
    if fmi_version == 3:
        xml = partial(model_description3_xml, token=token, relations=relations)
    else:
        n = len(relations)
        xml = partial(model_description_xml, guid=token, source_files=sources, n_event_indicators=n)
    tool = f"tsid-fmu {_version()}"
    return xml(prep.model, prep.causal, step_size=prep.step_size, generation_tool=tool)


def write_fmu(prep: Prepared, out: Path, fmi_version: int = 2) -> Path:
    """Write, compile and pack one FMU.

    Parameters
    ----------
    prep : Prepared
        The model from :func:`prepare`.
    out : Path
        The ``.fmu`` file to write.
    fmi_version : int, optional
        2 or 3.

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    BuildError
        If the version is not supported or compiling fails.
    """
    from .codegen import generate_c
    from .model_description3 import build_description_xml
    from .packaging import C_DIR, compile_binary, fmi_platform, wrapper_files, zip_fmu

    if fmi_version not in (2, 3):
        raise BuildError(f"FMI version {fmi_version} is not supported (2 or 3)")
    model, ident = prep.model, prep.model.short_name
    token = _token(prep, fmi_version)
    plat, _ = fmi_platform(fmi_version)
    with tempfile.TemporaryDirectory(prefix=f"tsid_build_{ident}_") as tmp:
        root = Path(tmp) / "fmu"
        src = root / "sources"
        src.mkdir(parents=True)
        files = wrapper_files(fmi_version)
        for f in files:
            shutil.copy2(C_DIR / f, src / Path(f).name)
        generated = generate_c(
            model, prep.causal, src, guid=token, step_size=prep.step_size, causal_me=prep.causal_me
        )
        sources = [f for f in files if f.endswith(".c")] + generated
        if fmi_version == 3:
            (src / "buildDescription.xml").write_text(
                build_description_xml(ident, sources), encoding="utf-8"
            )
        xml = _model_description(prep, token, fmi_version, sources)
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
        shutil.copy2(prep.model_file, res / prep.model_file.name)
        compile_binary(src, ident, root / "binaries" / plat, generated, fmi_version=fmi_version)
        zip_fmu(root, out)
    return out
