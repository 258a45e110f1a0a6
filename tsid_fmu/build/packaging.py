"""Compile the C sources of an FMU and pack the FMU archive."""

from __future__ import annotations

import os
import platform
import shlex
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

from tsid_fmu.errors import BuildError

__all__ = [
    "C_DIR",
    "WRAPPER_FILES",
    "WRAPPER_FILES3",
    "compile_binary",
    "fmi_platform",
    "wrapper_files",
    "zip_fmu",
]

#: Directory of the hand-written, generic C wrappers; the FMI 2.0 and 3.0 headers, as
#: published by the Modelica Association (2-Clause BSD), are in its ``third_party/``.
C_DIR = Path(__file__).resolve().parent / "c"

#: The model-independent core shared by both wrappers.
_CORE_FILES = ["tsid_core.c", "tsid_core.h"]

#: Files copied from :data:`C_DIR` into every FMI 2.0 FMU's ``sources/`` (flat).
WRAPPER_FILES = [
    "fmi2Functions.c",
    *_CORE_FILES,
    "third_party/fmi2Functions.h",
    "third_party/fmi2FunctionTypes.h",
    "third_party/fmi2TypesPlatform.h",
]

#: Files copied from :data:`C_DIR` into every FMI 3.0 FMU's ``sources/`` (flat).
WRAPPER_FILES3 = [
    "fmi3Functions.c",
    *_CORE_FILES,
    "third_party/fmi3Functions.h",
    "third_party/fmi3FunctionTypes.h",
    "third_party/fmi3PlatformTypes.h",
]


def wrapper_files(fmi_version: int) -> list[str]:
    """Return the wrapper files of an FMI version (C files first).

    Parameters
    ----------
    fmi_version : int
        2 or 3.

    Returns
    -------
    list of str
        Paths relative to :data:`C_DIR`; each goes into ``sources/`` under its name.
    """
    return WRAPPER_FILES3 if fmi_version == 3 else WRAPPER_FILES


# Own, hand-written code must compile without any warning.
_STRICT = ["-Wall", "-Wextra", "-Wpedantic", "-Werror"]
# CasADi-generated code: warnings on, the harmless ones it is known to trigger tolerated.
_TOLERANT = [
    "-Wall",
    "-Wextra",
    "-Wno-unused-parameter",
    "-Wno-unused-function",
    "-Wno-unused-variable",
    "-Wno-unused-but-set-variable",
]


def fmi_platform(fmi_version: int = 2) -> tuple[str, str]:
    """Return the platform folder name of ``binaries/`` and the shared-library suffix.

    Parameters
    ----------
    fmi_version : int, optional
        2 (``linux64``) or 3 (platform tuple ``x86_64-linux``).

    Returns
    -------
    tuple of str
        E.g. ``("linux64", ".so")``.

    Raises
    ------
    BuildError
        On a platform the build does not support.
    """
    bits = "64" if sys.maxsize > 2**32 else "32"
    machine = platform.machine().lower()
    arch = {"amd64": "x86_64", "arm64": "aarch64", "i686": "x86", "i386": "x86"}.get(
        machine, machine
    )
    if sys.platform.startswith("linux"):
        return (f"{arch}-linux" if fmi_version == 3 else f"linux{bits}"), ".so"
    if sys.platform == "darwin":
        return (f"{arch}-darwin" if fmi_version == 3 else f"darwin{bits}"), ".dylib"
    raise BuildError(
        f"building FMU binaries on {sys.platform}/{platform.machine()} is not supported; "
        "build on Linux or macOS, or compile the FMU's sources/ with 'fmpy compile'"
    )


def _compiler() -> list[str]:
    cc = os.environ.get("CC", "")
    cmd = shlex.split(cc) if cc else []
    if not cmd:
        for cand in ("cc", "gcc", "clang"):
            if shutil.which(cand):
                cmd = [cand]
                break
    if not cmd or not shutil.which(cmd[0]):
        raise BuildError(
            "no C compiler found (tried $CC, cc, gcc, clang); install one to build FMUs"
        )
    return cmd


def _run(cmd: list[str], cwd: Path) -> None:
    try:
        proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, check=False)
    except OSError as exc:
        raise BuildError(f"compiler command failed to start: {shlex.join(cmd)}: {exc}") from exc
    if proc.returncode != 0:
        out = (proc.stderr or proc.stdout).strip()
        raise BuildError(
            f"compiler command failed (exit {proc.returncode}): {shlex.join(cmd)}\n{out}"
        )


def compile_binary(
    sources_dir: Path,
    model_identifier: str,
    out_dir: Path,
    generated: list[str],
    *,
    fmi_version: int = 2,
) -> Path:
    """Compile the wrapper and the generated model part into a shared library.

    Parameters
    ----------
    sources_dir : Path
        The FMU's ``sources/`` (wrapper, headers and generated files).
    model_identifier : str
        FMI model identifier, the base name of the library.
    out_dir : Path
        Directory that receives the library.
    generated : list of str
        Generated ``.c`` files in ``sources_dir``.
    fmi_version : int, optional
        2 or 3: which wrapper to compile.

    Returns
    -------
    Path
        The shared library.

    Raises
    ------
    BuildError
        Naming the compiler command that failed and its output.
    """
    _, suffix = fmi_platform(fmi_version)
    cc = _compiler()
    out_dir.mkdir(parents=True, exist_ok=True)
    common = ["-O2", "-fPIC", "-std=c99", "-fvisibility=hidden", "-I", "."]
    objs = []
    own = [f for f in wrapper_files(fmi_version) if f.endswith(".c")]
    for src in [*own, *generated]:
        flags = _STRICT if src in [*own, "model.c"] else _TOLERANT
        obj = src[:-2] + ".o"
        _run([*cc, *common, *flags, "-c", src, "-o", obj], sources_dir)
        objs.append(obj)
    lib = out_dir / f"{model_identifier}{suffix}"
    link = [*cc, "-shared", "-o", str(lib), *objs, "-lm"]
    _run(link, sources_dir)
    for obj in objs:
        (sources_dir / obj).unlink(missing_ok=True)
    return lib


def zip_fmu(root: Path, fmu_path: Path) -> Path:
    """Pack the directory ``root`` into the FMU archive ``fmu_path``.

    Entries are sorted and carry a fixed time stamp, so that identical inputs give an
    identical archive.

    Parameters
    ----------
    root : Path
        Directory holding ``modelDescription.xml``, ``binaries/``, ``sources/``, ...
    fmu_path : Path
        The ``.fmu`` file to write (parent directories are created).

    Returns
    -------
    Path
        ``fmu_path``.
    """
    fmu_path.parent.mkdir(parents=True, exist_ok=True)
    tmp = fmu_path.with_name(fmu_path.name + ".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for path in sorted(p for p in root.rglob("*") if p.is_file()):
            rel = path.relative_to(root).as_posix()
            info = zipfile.ZipInfo(rel, date_time=(2020, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if path.suffix in (".so", ".dylib") else 0o644) << 16
            zf.writestr(info, path.read_bytes())
    os.replace(tmp, fmu_path)
    return fmu_path
