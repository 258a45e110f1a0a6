"""Each FMU file is extracted once per process and its folder lent to one session at a time.

Issue 25: every session used to extract the FMU into a new folder and so load one more
copy of its library; pythonfmu's copies are never unloaded and abort the process at
exit.  Here: sessions opened one after the other share one folder (one library file),
sessions open at the same time get one each, a changed file is extracted afresh, the
folders go at the process's exit, and a forked child neither reuses nor removes its
parent's folders.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest
from fmu_factory import build_c_fmu, copy_without

import tsid_fmu.fmu.extraction as extraction
from tsid_fmu.errors import FMUError
from tsid_fmu.fmu import FMUSession

REPO = Path(__file__).resolve().parents[1]
T = np.linspace(0.0, 0.1, 11)


@pytest.fixture(scope="module")
def lag(tmp_path_factory) -> Path:
    return build_c_fmu(tmp_path_factory.mktemp("lag"), "Lag", interfaces=("cs",))


@pytest.fixture
def own_tmp(tmp_path, monkeypatch) -> Path:
    d = tmp_path / "tmp"
    d.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(d))
    return d


def _run(fmu: Path, tau: float = 0.3) -> tuple[Path, np.ndarray]:
    with FMUSession(fmu, ["u"], ["y"], parameters=["tau"]) as s:
        assert s.tempdir is not None
        return s.tempdir, s.simulate(T, np.ones(T.size), {"tau": tau})


def test_sessions_one_after_the_other_share_one_folder(lag, tmp_path, own_tmp):
    fmu = tmp_path / "a.fmu"
    fmu.write_bytes(lag.read_bytes())
    first, y1 = _run(fmu)
    second, y2 = _run(fmu)
    assert first == second and first.parent == own_tmp and first in extraction.folders()
    np.testing.assert_array_equal(y1, y2)
    # the same file under another spelling of its path is the same file
    third, _ = _run(tmp_path / "." / "a.fmu")
    assert third == first
    assert [p.name for p in own_tmp.iterdir()] == [first.name]


def test_sessions_open_together_get_a_folder_each(lag, tmp_path, own_tmp):
    fmu = tmp_path / "b.fmu"
    fmu.write_bytes(lag.read_bytes())
    with (
        FMUSession(fmu, ["u"], ["y"]) as a,
        FMUSession(fmu, ["u"], ["y"]) as b,
    ):
        assert a.tempdir != b.tempdir  # an FMU may allow one instance per library copy
        ya, yb = a.simulate(T, np.ones(11), {}), b.simulate(T, np.ones(11), {})
        np.testing.assert_array_equal(ya, yb)
        held = {a.tempdir, b.tempdir}
    later = {_run(fmu)[0], _run(fmu)[0]}
    assert later <= held and len(list(own_tmp.iterdir())) == 2


def test_a_changed_file_is_extracted_afresh(lag, tmp_path, own_tmp):
    fmu = tmp_path / "c.fmu"
    fmu.write_bytes(lag.read_bytes())
    before, _ = _run(fmu)
    data = fmu.read_bytes()
    fmu.write_bytes(data)  # same bytes, but written again: a new modification time
    st = fmu.stat()
    os.utime(fmu, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))
    after, _ = _run(fmu)
    assert after != before and before.is_dir()  # the old one stays until exit


def test_a_refused_or_missing_file_leaves_no_folder(tmp_path, own_tmp):
    bad = tmp_path / "bad.fmu"
    bad.write_bytes(b"not a zip")
    with pytest.raises(FMUError, match="not an FMU"):
        FMUSession(bad, ["u"], ["y"])
    with pytest.raises(FMUError, match="FMU file not found"):
        FMUSession(tmp_path / "missing.fmu", ["u"], ["y"])
    assert not list(own_tmp.iterdir())


_CHILD = """
import os, sys, tempfile
from pathlib import Path
import numpy as np
from tsid_fmu.fmu import FMUSession
import tsid_fmu.fmu.extraction as extraction

fmu, report = Path(sys.argv[1]), Path(sys.argv[2])
def run():
    with FMUSession(fmu, ["u"], ["y"], parameters=["tau"]) as s:
        s.simulate(np.linspace(0, 0.1, 11), np.ones(11), {"tau": 0.3})
        return s.tempdir
parent = run()
pid = os.fork()
if pid == 0:  # the child opens the FMU too, then exits through Python's atexit
    child = run()
    (report.parent / "child.txt").write_text(str(child))
    sys.exit(0)
_, status = os.waitpid(pid, 0)
child = Path((report.parent / "child.txt").read_text())
report.write_text(
    f"{os.waitstatus_to_exitcode(status)} {parent.is_dir()} {child != parent} "
    f"{child.exists()} {parent}"
)
"""


@pytest.mark.slow
def test_folders_go_at_exit_and_a_forked_child_leaves_the_parents(lag, tmp_path):
    """The creating process removes its folders at exit; a forked child only its own."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    report = tmp_path / "report.txt"
    proc = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(_CHILD), str(lag), str(report)],
        cwd=REPO,
        env={**os.environ, "TMPDIR": str(tmp), "PYTHONPATH": str(REPO)},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    code, parent_kept, own, child_left, parent = report.read_text().split()
    # the child exited 0, the parent's folder survived the child's exit, the child
    # extracted into a folder of its own and removed it at its exit
    assert (code, parent_kept, own, child_left) == ("0", "True", "True", "False")
    assert not Path(parent).exists()  # and the parent removed its own at its exit
    assert not list(tmp.iterdir())


def _with_ballast(src: Path, dst: Path, members: dict[str, bytes]) -> Path:
    import zipfile

    with zipfile.ZipFile(src) as a, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as b:
        for info in a.infolist():
            b.writestr(info, a.read(info))
        for name, data in members.items():
            b.writestr(name, data)
    return dst


def test_only_what_a_simulation_reads_is_written(lag, tmp_path, own_tmp):
    # issue 25: a 1.9 GiB member took 80 s and 4.7 GB of temporary disk; documentation,
    # icons, other platforms' binaries and stray root files are checked but not written
    big = bytes(8 * 1024**2)  # compresses to a few kB
    fmu = _with_ballast(
        lag,
        tmp_path / "ballast.fmu",
        {
            "documentation/manual.bin": big,
            "terminalsAndIcons/icon.bin": big,
            "binaries/win64/Lag.dll": big,
            "sources/big.c": big,
            "zero.bin": big,
            "resources/table.txt": b"1 2 3\n",
            "extra/org.example/meta.txt": b"x",
        },
    )
    folder, y = _run(fmu)
    written = {p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()}
    assert "resources/table.txt" in written and "extra/org.example/meta.txt" in written
    assert "modelDescription.xml" in written and any(w.startswith("binaries/") for w in written)
    for skipped in ("documentation/", "terminalsAndIcons/", "binaries/win64/", "sources/", "zero"):
        assert not any(w.startswith(skipped) for w in written), skipped
    assert sum(p.stat().st_size for p in folder.rglob("*") if p.is_file()) < len(big)
    _, plain = _run(lag)
    np.testing.assert_array_equal(y, plain)


def test_an_fmu_without_a_binary_here_keeps_its_sources_and_every_binary(tmp_path):
    from tsid_fmu.fmu.archive import safe_extract

    fmu = tmp_path / "src.fmu"
    import zipfile

    with zipfile.ZipFile(fmu, "w") as z:
        z.writestr("modelDescription.xml", "<fmiModelDescription/>")
        z.writestr("sources/model.c", "int x;")
        z.writestr("binaries/win64/M.dll", b"MZ")
        z.writestr("documentation/index.html", "<p/>")
    out = safe_extract(fmu, tmp_path / "out", running=True)
    assert (out / "sources/model.c").is_file() and (out / "binaries/win64/M.dll").is_file()
    assert not (out / "documentation").exists()
    full = safe_extract(fmu, tmp_path / "all")
    assert (full / "documentation/index.html").is_file()


def test_an_fmu_that_needs_its_empty_resources_folder_runs(tmp_path):
    """JModelica.org's FMUs fail to instantiate without ``resources/`` (issue 43).

    The FMU's archive holds the folder as an empty member; the extraction for running
    kept only files, so the folder was missing and the instance was never made.
    """
    fmu = build_c_fmu(tmp_path, "NeedsRes", interfaces=("cs",), needs_resources=True)
    t = np.arange(0, 1.0 + 1e-9, 0.01)
    with FMUSession(fmu, ["u"], ["y"], parameters=["tau"]) as session:
        y = session.simulate(t, np.ones((t.size, 1)), {"tau": 0.3})
    assert np.isfinite(y).all() and y[-1, 0] > 0.9
    # without the folder in the archive at all, it runs too: the standard hands it over
    bare = copy_without(fmu, tmp_path / "Bare.fmu", "resources")
    with FMUSession(bare, ["u"], ["y"], parameters=["tau"]) as session:
        assert np.isfinite(session.simulate(t, np.ones((t.size, 1)), {"tau": 0.3})).all()


def test_a_failed_instantiation_names_the_cause_the_fmu_gives_with_logging_on(tmp_path):
    """An FMU that refuses silently is asked again with logging on (issue 43).

    Extracted by hand without ``resources/``, the FMU returns no instance; it says why
    only when ``loggingOn`` is true, as many exporters do.
    """
    fmu = build_c_fmu(tmp_path, "NeedsRes", interfaces=("cs",), needs_resources=True)
    folder = tmp_path / "by_hand"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(folder)
    shutil.rmtree(folder / "resources")
    with pytest.raises(FMUError) as info:
        FMUSession(folder, ["u"], ["y"], parameters=["tau"])
    message = str(info.value)
    assert (
        "instantiation failed: Failed to instantiate model (asked again with logging on)" in message
    )
    assert "[Fatal] logStatusFatal: cannot open the resources folder" in message
