"""Hostile FMU archives: each is refused with an FMUError naming the FMU and the member.

Path traversal (``../``, absolute, Windows drive and backslash paths), symbolic links
and special files, zip bombs (declared sizes, and headers that lie about them), corrupt,
encrypted and unsupported members, a missing ``modelDescription.xml``, a binary only for
another platform, and a binary whose shared-library dependency is missing.  The bombs
are small: the size limit is lowered for the test or the header sizes are forged.
"""

from __future__ import annotations

import stat
import struct
import tempfile
import zipfile
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmu_factory import build_c_fmu, build_stub_library, copy_without

import tsid_fmu.fmu.extraction as extraction
from tsid_fmu.cli import main
from tsid_fmu.errors import FMUError
from tsid_fmu.fmu import FMUSession, safe_extract
from tsid_fmu.fmu import archive as safety

MIB = 1 << 20


@pytest.fixture(scope="module")
def lag(tmp_path_factory) -> Path:
    return build_c_fmu(tmp_path_factory.mktemp("lag"), "Lag", interfaces=("cs",))


@pytest.fixture(autouse=True)
def private_tmp(tmp_path, monkeypatch):
    """Sessions extract into a private temp folder, so leftovers can be counted."""
    tmp = tmp_path / "sessiontmp"
    tmp.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(tmp))
    yield tmp
    # an accepted FMU's folder is kept for the process's next session of it
    # (multiprocessing's own pymp-* folder, made on first use, is not an extraction's)
    made = {p for p in tmp.iterdir() if p.name.startswith(extraction.PREFIX)}
    leftovers = made - set(extraction.folders())
    assert not leftovers, "a refused FMU left its extraction folder behind"


def with_members(src: Path, dest: Path, extra: list[tuple[str | zipfile.ZipInfo, bytes]]) -> Path:
    """Copy ``src`` to ``dest`` and append the ``extra`` members."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dest, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            zout.writestr(item, zin.read(item.filename))
        for name, data in extra:
            zout.writestr(name, data)
    return dest


def patch_member(path: Path, member: str, **fields: int) -> None:
    """Overwrite header fields of ``member`` in both its local and central headers.

    ``fields`` may hold ``file_size``, ``compress_size``, ``flags``, ``method``, ``crc``.
    """
    raw = bytearray(path.read_bytes())
    name = member.encode()
    # offsets inside the local (PK\3\4) and central (PK\1\2) headers
    local = {"flags": (6, "<H"), "method": (8, "<H"), "crc": (14, "<I"),
             "compress_size": (18, "<I"), "file_size": (22, "<I")}  # fmt: skip
    central = {"flags": (8, "<H"), "method": (10, "<H"), "crc": (16, "<I"),
               "compress_size": (20, "<I"), "file_size": (24, "<I")}  # fmt: skip
    for sig, offsets, name_at in ((b"PK\x03\x04", local, 30), (b"PK\x01\x02", central, 46)):
        start = 0
        while (pos := raw.find(sig, start)) >= 0:
            start = pos + 4
            if raw[pos + name_at : pos + name_at + len(name)] == name:
                for key, value in fields.items():
                    off, fmt = offsets[key]
                    struct.pack_into(fmt, raw, pos + off, value)
                break
        else:
            raise AssertionError(f"{member} not found after {sig!r}")
    path.write_bytes(bytes(raw))


def refused(fmu: Path, *patterns: str) -> str:
    """Open ``fmu`` in a session; assert an FMUError naming the file and ``patterns``."""
    with pytest.raises(FMUError) as info:
        FMUSession(fmu, ["u"], ["y"])
    message = str(info.value)
    assert fmu.name in message
    for pattern in patterns:
        assert pattern in message, message
    return message


# ---------------------------------------------------------------------------- positive


def test_safe_extract_matches_extractall(lag, tmp_path):
    out = safe_extract(lag, tmp_path / "x")
    assert out == (tmp_path / "x").resolve()
    with zipfile.ZipFile(lag) as zf:
        names = {n for n in zf.namelist() if not n.endswith("/")}
        for n in names:
            assert (out / n).read_bytes() == zf.read(n)
    assert {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()} == names


def test_backslash_names_from_windows_zippers_still_work(lag, tmp_path):
    win = tmp_path / "win.fmu"
    with zipfile.ZipFile(lag) as zin, zipfile.ZipFile(win, "w") as zout:
        for item in zin.infolist():
            zout.writestr(item.filename.replace("/", "\\"), zin.read(item.filename))
    t = np.linspace(0, 1, 11)
    with FMUSession(win, ["u"], ["y"], parameters=["tau"]) as s:
        y = s.simulate(t, np.ones(11), {"tau": 0.5})
    assert y[-1, 0] == pytest.approx(1 - np.exp(-2))


# ---------------------------------------------------------------------------- names


@pytest.mark.parametrize(
    "member",
    [
        "../evil.txt",
        "resources/../../evil.txt",
        "resources/./../../../evil.txt",
        "/tmp/tsid_evil.txt",
        "C:/evil.dll",
        "C:\\evil.dll",
        "c:evil.dll",
        "..\\..\\evil.txt",
        "resources\\..\\..\\evil.txt",
        "resources/C:/evil.dll",
    ],
)
def test_path_traversal_is_refused(lag, tmp_path, member):
    fmu = with_members(lag, tmp_path / "traversal.fmu", [(member, b"owned")])
    message = refused(fmu, repr(member), "refusing the FMU")
    assert "outside the extraction folder" in message
    with pytest.raises(FMUError, match="refusing the FMU"):
        safe_extract(fmu, tmp_path / "a" / "b" / "dest")
    # nothing was written anywhere, not even the harmless members
    assert not (tmp_path / "a" / "b" / "dest").exists()
    assert not list(tmp_path.rglob("evil*")) and not Path("/tmp/tsid_evil.txt").exists()


def _typed(name: str, mode: int) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name)
    info.create_system = 3
    info.external_attr = mode << 16
    return info


@pytest.mark.parametrize(
    ("mode", "what"),
    [
        (stat.S_IFLNK | 0o777, "symbolic link"),
        (stat.S_IFIFO | 0o644, "special file"),
        (stat.S_IFCHR | 0o644, "special file"),
    ],
)
def test_symlinks_and_special_files_are_refused(lag, tmp_path, mode, what):
    fmu = with_members(
        lag,
        tmp_path / "link.fmu",
        [(_typed("resources/data", mode), b"/etc/passwd"), ("resources/data/x", b"1")],
    )
    refused(fmu, "'resources/data'", what)


def test_permission_bits_without_file_type_are_regular_files(lag, tmp_path):
    fmu = with_members(lag, tmp_path / "perm.fmu", [(_typed("resources/a.txt", 0o600), b"1")])
    assert (safe_extract(fmu, tmp_path / "x") / "resources" / "a.txt").read_bytes() == b"1"


# ---------------------------------------------------------------------------- sizes


def test_zip_bomb_refused_from_declared_size(lag, tmp_path, monkeypatch):
    zeros = b"\0" * (4 * MIB)  # deflates to ~4 KiB
    fmu = with_members(lag, tmp_path / "bomb.fmu", [("resources/zeros.bin", zeros)])
    assert fmu.stat().st_size < 100_000
    monkeypatch.setattr(safety, "MAX_BYTES", MIB)
    refused(fmu, "'resources/zeros.bin'", "4,194,304 bytes", "1,048,576", "zip bomb")
    with pytest.raises(FMUError, match=r"zeros\.bin"):
        safe_extract(fmu, tmp_path / "x", max_bytes=MIB)
    assert not (tmp_path / "x").exists()  # refused before anything was written
    safe_extract(fmu, tmp_path / "y", max_bytes=8 * MIB)  # fine with a larger limit


def test_many_members_adding_up_are_refused(lag, tmp_path):
    parts = [(f"resources/part{i}.bin", b"\0" * (MIB // 2)) for i in range(3)]
    fmu = with_members(lag, tmp_path / "sum.fmu", parts)
    with pytest.raises(FMUError, match=r"the archive \(largest member 'resources/part"):
        safe_extract(fmu, tmp_path / "x", max_bytes=MIB)
    with pytest.raises(FMUError, match=r"members, more than the limit of 3"):
        safe_extract(fmu, tmp_path / "x", max_members=3)


def test_default_limit_refuses_a_forged_huge_declaration(lag, tmp_path):
    fmu = with_members(lag, tmp_path / "huge.fmu", [("resources/huge.bin", b"tiny")])
    patch_member(fmu, "resources/huge.bin", file_size=3 * 1024**3)
    assert safety.MAX_BYTES == 2 * 1024**3
    refused(fmu, "'resources/huge.bin'", "3,221,225,472 bytes")


def test_header_that_understates_the_size_is_caught_while_extracting(lag, tmp_path):
    # 8 MiB of zeros declared as 1000 bytes: the declared total passes the limit, the
    # bytes actually decompressed must not
    fmu = with_members(lag, tmp_path / "liar.fmu", [("resources/liar.bin", b"\0" * (8 * MIB))])
    patch_member(fmu, "resources/liar.bin", file_size=1000)
    with pytest.raises(FMUError, match=r"member 'resources/liar.bin' (is damaged|expands beyond)"):
        safe_extract(fmu, tmp_path / "x", max_bytes=MIB)
    written = sum(p.stat().st_size for p in (tmp_path / "x").rglob("*") if p.is_file())
    assert written < 2 * MIB
    refused(fmu, "'resources/liar.bin'")


# ---------------------------------------------------------------------------- damage


def test_corrupt_encrypted_and_unsupported_members(lag, tmp_path):
    payload = bytes(range(256)) * 64
    base = with_members(lag, tmp_path / "base.fmu", [("resources/blob.bin", payload)])
    raw = bytearray(base.read_bytes())
    at = raw.find(b"resources/blob.bin") + len("resources/blob.bin")
    raw[at : at + 40] = b"\xff" * 40  # garbage deflate stream
    corrupt = tmp_path / "corrupt.fmu"
    corrupt.write_bytes(bytes(raw))
    refused(corrupt, "'resources/blob.bin'", "damaged")

    encrypted = tmp_path / "encrypted.fmu"
    encrypted.write_bytes(base.read_bytes())
    patch_member(encrypted, "resources/blob.bin", flags=1)
    refused(encrypted, "'resources/blob.bin' is encrypted")

    unsupported = tmp_path / "method.fmu"
    unsupported.write_bytes(base.read_bytes())
    patch_member(unsupported, "resources/blob.bin", method=99)
    refused(unsupported, "'resources/blob.bin' uses ZIP compression method 99")


def test_truncated_archive(lag, tmp_path):
    cut = tmp_path / "cut.fmu"
    cut.write_bytes(lag.read_bytes()[: lag.stat().st_size // 2])
    with pytest.raises(FMUError, match=r"cut.fmu: not an FMU"):
        FMUSession(cut, ["u"], ["y"])


# ---------------------------------------------------------------------------- content


def test_missing_model_description(lag, tmp_path):
    fmu = copy_without(lag, tmp_path / "nomd.fmu", "modelDescription.xml")
    refused(fmu, "modelDescription.xml is missing")


def test_model_description_in_a_subfolder_gets_a_hint(lag, tmp_path):
    nested = tmp_path / "nested.fmu"
    with zipfile.ZipFile(lag) as zin, zipfile.ZipFile(nested, "w") as zout:
        for item in zin.infolist():
            zout.writestr("Lag/" + item.filename, zin.read(item.filename))
    refused(nested, "'Lag/modelDescription.xml'", "zip the contents")


def test_binary_only_for_another_platform(lag, tmp_path):
    win = tmp_path / "winonly.fmu"
    with zipfile.ZipFile(lag) as zin, zipfile.ZipFile(win, "w") as zout:
        zout.writestr("modelDescription.xml", zin.read("modelDescription.xml"))
        zout.writestr("binaries/win64/Lag.dll", b"MZ not really a dll")
    message = refused(win, f"binaries/{fmpy.platform}/Lag.so", "platforms present: win64")
    assert "compile" not in message  # no sources, nothing to compile
    with_src = tmp_path / "winsrc.fmu"
    with zipfile.ZipFile(lag) as zin, zipfile.ZipFile(with_src, "w") as zout:
        for item in zin.infolist():
            if not item.filename.startswith("binaries/"):
                zout.writestr(item, zin.read(item.filename))
        zout.writestr("binaries/win64/Lag.dll", b"MZ")
    refused(with_src, "platforms present: win64", "compile")


def test_binary_with_missing_dependency_names_the_library(tmp_path):
    stub = build_stub_library(tmp_path / "dep", "tsidgone")
    fmu = build_c_fmu(tmp_path, "NeedsGone", interfaces=("cs",), link_library=stub)
    stub.unlink()
    refused(fmu, "libtsidgone.so", "LD_LIBRARY_PATH")


def test_cli_prints_one_line_for_a_hostile_fmu(lag, tmp_path, capsys):
    with_members(lag, tmp_path / "evil.fmu", [("../../evil.txt", b"x")])
    (tmp_path / "d.csv").write_text("time,u,y\n0,0,0\n0.1,1,0.1\n0.2,1,0.2\n0.3,1,0.3\n")
    study = tmp_path / "s.toml"
    study.write_text(
        '[study]\nfmu = "evil.fmu"\n[data]\nfile = "d.csv"\ninputs = { u = "u" }\n'
        'outputs = { y = "y" }\n[method]\nweighting = "none"\n'
        "[parameters]\ntau = { levels = [0.1, 0.2, 0.3] }\n"
    )
    assert main(["identify", str(study), "--out", str(tmp_path / "o"), "-q", "--no-plots"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("tsid: error: ")
    assert "evil.fmu" in err and "'../../evil.txt'" in err and "Traceback" not in err
