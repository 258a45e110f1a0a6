"""Load an extracted FMU's shared library and find the functions the step loops call.

Loading goes through FMPy's ``FMU2Slave``/``FMU2Model``/``FMU3Slave``/``FMU3Model``
wrappers (their FMI status checks are used for setup).  Before that the library is
opened once with :mod:`ctypes`, so that a missing dependency is reported by name
instead of FMPy's bare exception.

Libraries made by pythonfmu export ``finalizePythonInterpreter``, which their own
destructor calls at ``exit()`` -- after a C++ static destructor has already destroyed
the object it resets, a double free that aborts the process (``corrupted double-linked
list``, exit status 134) after the study's results are written.  Such a library is kept
loaded and its ``finalizePythonInterpreter`` is called once at Python's exit
(:mod:`atexit` runs before the C++ static destructors, while the process is whole), so
that the destructors find nothing left to free.  Other libraries are not touched.
"""

from __future__ import annotations

import atexit
import ctypes
import os
import re
import threading
from pathlib import Path
from typing import Any

import tsid_fmu.fmu.steploop as steploop
from tsid_fmu.errors import FMUError

__all__ = ["FINALIZE", "finalize_libraries", "load_fmu", "loop_functions"]

#: the function pythonfmu's libraries export to release their interpreter state
FINALIZE = "finalizePythonInterpreter"

_DEP_RE = re.compile(r"([^\s:]+\.(?:so|dylib|dll)(?:\.[0-9.]+)?): cannot open shared object")


def _missing_dependency(message: str, library: Path) -> str | None:
    """Name the dependency a ``dlopen`` error message complains about, if any."""
    for match in _DEP_RE.finditer(message):
        name = match.group(1)
        if Path(name).name != library.name:
            return name
    return None


_finalizers: dict[str, ctypes.CDLL] = {}
_finalizers_lock = threading.Lock()


def _keep_for_exit(probe: ctypes.CDLL) -> bool:
    """Keep ``probe`` loaded, to call its :data:`FINALIZE` at exit, if it exports one.

    Returns True if it does (the caller must then not free it).  A library already kept
    (the same file, so the same handle) is kept once.
    """
    if not hasattr(probe, FINALIZE):  # ctypes looks the symbol up with dlsym
        return False
    with _finalizers_lock:
        if not _finalizers:
            atexit.register(finalize_libraries)
        if probe._name in _finalizers:
            return False  # the handle kept already holds it loaded: free this one
        _finalizers[probe._name] = probe
    return True


def finalize_libraries() -> None:
    """Call :data:`FINALIZE` of every library that exports it, once (at Python's exit).

    Runs before the C++ static destructors of ``exit()``, so a pythonfmu library's own
    destructor finds its interpreter state already released instead of freeing it a
    second time.  Safe to call again: each library is called once.
    """
    with _finalizers_lock:
        libraries = list(_finalizers.values())
        _finalizers.clear()
    for library in libraries:
        getattr(library, FINALIZE)()


def _fmpy_class(major: int, interface: str) -> type:
    if major == 2:
        from fmpy.fmi2 import FMU2Model, FMU2Slave

        return FMU2Slave if interface == "cs" else FMU2Model
    from fmpy.fmi3 import FMU3Model, FMU3Slave

    return FMU3Slave if interface == "cs" else FMU3Model


def _library_path(fmu: str, unzipdir: Path, identifier: str, major: int) -> tuple[Path, str]:
    import fmpy

    platform_dir = fmpy.platform if major == 2 else fmpy.platform_tuple
    library = unzipdir / "binaries" / platform_dir / (identifier + fmpy.sharedLibraryExtension)
    if not library.is_file():
        bindir = unzipdir / "binaries"
        present = sorted(p.name for p in bindir.iterdir()) if bindir.is_dir() else []
        raise FMUError(
            f"{fmu}: no binary for this platform: expected "
            f"binaries/{platform_dir}/{library.name}; platforms present: "
            f"{', '.join(present) if present else 'none'}"
            + (
                " (the FMU only contains sources; compile it for this platform)"
                if (unzipdir / "sources").is_dir()
                else ""
            )
        )
    return library, f"binaries/{platform_dir}/{library.name}"


def load_fmu(fmu: str, unzipdir: Path, md: Any, interface: str, major: int) -> Any:
    """Return FMPy's FMU object for the extracted FMU, its library loaded.

    Parameters
    ----------
    fmu : str
        The FMU's file name, for messages.
    unzipdir : pathlib.Path
        The folder the FMU was extracted to.
    md : fmpy.model_description.ModelDescription
        Its model description.
    interface : {"cs", "me"}
        Co-Simulation or Model Exchange.
    major : {2, 3}
        FMI major version.

    Raises
    ------
    FMUError
        No binary for this platform, or the library (or a library it needs) cannot be
        loaded.
    """
    desc = md.coSimulation if interface == "cs" else md.modelExchange
    identifier = desc.modelIdentifier
    library, where = _library_path(fmu, unzipdir, identifier, major)
    try:
        probe = ctypes.CDLL(str(library))
    except OSError as exc:
        dep = _missing_dependency(str(exc), library)
        reason = (
            f"it needs {dep}, which cannot be found (install it or add its "
            "folder to LD_LIBRARY_PATH)"
            if dep
            else str(exc)
        )
        raise FMUError(f"{fmu}: cannot load {where}: {reason}") from exc
    keep = _keep_for_exit(probe)
    cwd = os.getcwd()
    try:
        return _fmpy_class(major, interface)(
            guid=md.guid,
            modelIdentifier=identifier,
            unzipDirectory=str(unzipdir),
            instanceName=identifier,
        )
    except Exception as exc:  # FMPy raises bare Exception, AttributeError on symbols
        raise FMUError(f"{fmu}: cannot load {where}: {exc}") from exc
    finally:
        os.chdir(cwd)
        if not keep:
            from fmpy import freeLibrary

            freeLibrary(probe._handle)


def _not_available(*args: Any) -> int:
    return 3  # fmi2Error: the FMU does not export the function


_SETDER_MISSING = steploop.FMI2_SETDER(_not_available)


def loop_functions(dll: ctypes.CDLL, major: int) -> tuple[Any, ...]:
    """Return the raw function pointers the step loop of FMI ``major`` calls.

    FMI 2.0: ``(fmi2SetReal, fmi2DoStep, fmi2GetReal, fmi2SetRealInputDerivatives)``
    (a stand-in that returns ``fmi2Error`` when the FMU lacks the last one; the loop
    calls it only for FMUs that declare ``canInterpolateInputs``).  FMI 3.0:
    ``(fmi3SetFloat64, fmi3DoStep, fmi3GetFloat64)``.
    """
    sl = steploop
    if major == 3:
        return (
            sl.raw(dll, "fmi3SetFloat64", sl.FMI3_SETGET),
            sl.raw(dll, "fmi3DoStep", sl.FMI3_DOSTEP),
            sl.raw(dll, "fmi3GetFloat64", sl.FMI3_SETGET),
        )
    try:
        set_der = sl.raw(dll, "fmi2SetRealInputDerivatives", sl.FMI2_SETDER)
    except AttributeError:
        set_der = _SETDER_MISSING
    return (
        sl.raw(dll, "fmi2SetReal", sl.FMI2_SETGET),
        sl.raw(dll, "fmi2DoStep", sl.FMI2_DOSTEP),
        sl.raw(dll, "fmi2GetReal", sl.FMI2_SETGET),
        set_der,
    )
