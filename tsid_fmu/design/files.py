"""The files of a design: the input to replay, a plot, the tables, JSON and reports.

``design_input.csv`` has the columns ``time`` and one per designed FMU input, at the
proposal's sample times: what a rig's controller replays. ``design.png`` shows the
input, the outputs the model predicts for it at the answer, and each parameter's 95 %
interval now and predicted with the proposal, relative to its value.

:func:`write_design` writes every file into a new folder beside the output folder and
then puts that folder in the output's place, so that the output folder holds one whole
design: no file of an earlier design stays beside the new ones, and an interrupted write
leaves the earlier design as it was. Two writes into one folder take turns (a lock file
``.<name>.lock`` beside it). The output folder is replaced only where it holds nothing
but a design's files.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from tsid_fmu.design.outcome import Design, width
from tsid_fmu.errors import StudyError

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: the replace alone keeps designs whole
    fcntl = None  # type: ignore[assignment]

__all__ = ["DESIGN_FILES", "check_output", "default_output", "plot_design", "write_design"]

DESIGN_FILES = frozenset({"design_input.csv", "design_structures_input.csv", "design.png",
                          "design.json", "design.md", "design.html"})  # fmt: skip
"""The files a design folder holds; a folder with others is not replaced."""


def default_output(result_dir: str | Path) -> Path:
    """Return the default output folder of a design of ``result_dir``.

    ``<result>.design`` beside the result folder: named after it, so that the designs of
    the results in one folder do not overwrite one another, and never inside it
    (``--result .`` included).
    """
    folder = Path(result_dir).resolve()
    return folder.parent / f"{folder.name or 'result'}.design"


def check_output(out: str | Path, result_dir: str | Path | None = None) -> Path:
    """Check, before any simulation, that a design can be written to ``out``; return it.

    ``out`` must not be the result folder or inside it, must be a folder (or not exist
    yet) holding only a design's files, and its parent must be writable (the new design
    is written beside it, then put in its place). The parent folders are made.

    Raises
    ------
    StudyError
        Naming ``out`` and what is wrong.
    """
    out = Path(out)
    try:
        where = out.resolve()
        inside = result_dir is not None and (
            where == Path(result_dir).resolve() or Path(result_dir).resolve() in where.parents
        )
        if inside:
            raise StudyError(
                f"design output {out}: is inside the result folder {result_dir}; choose "
                "another folder (-o)"
            )
        if where.exists():
            if not where.is_dir():
                raise StudyError(f"design output {out}: exists and is not a folder")
            others = sorted(p.name for p in where.iterdir() if p.name not in DESIGN_FILES)
            if others:
                shown = ", ".join(others[:3]) + (" ..." if len(others) > 3 else "")
                raise StudyError(
                    f"design output {out}: holds files that are not a design's ({shown}); "
                    "it is replaced as a whole, so choose an empty or new folder (-o)"
                )
        where.parent.mkdir(parents=True, exist_ok=True)
        os.rmdir(tempfile.mkdtemp(prefix=f".{where.name}.check-", dir=where.parent))
    except (OSError, ValueError) as exc:  # ValueError: a NUL in the path
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        raise StudyError(f"design output {out!s}: cannot write there ({reason})") from None
    return out


def plot_design(d: Design, path: Path) -> Path:
    """Draw the proposed input, the predicted outputs and the intervals before and after."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = 3 if d.proposal is not None else 1
    fig, axes = plt.subplots(rows, 1, figsize=(8, 2.4 * rows + 0.6), squeeze=False)
    axes = axes[:, 0]
    if d.proposal is not None:
        for i, name in enumerate(d.inputs):
            axes[0].plot(d.time, d.proposal.values[:, i], lw=0.7, label=name)
        axes[0].set_title(f"proposed input: {d.proposal.name}")
        axes[0].set_xlabel("time [s]")
        axes[0].legend(fontsize=8)
        out = d.predicted_outputs
        for k, name in enumerate(d.output_names):
            y = out[:, k]  # type: ignore[index]
            scale = max(float(np.max(np.abs(y))), 1e-300)
            axes[1].plot(d.time, y / scale, lw=0.7, label=f"{name} / {scale:.3g}")
        axes[1].set_title("outputs predicted at the answer")
        axes[1].set_xlabel("time [s]")
        axes[1].legend(fontsize=8)
    ax = axes[-1]
    y = np.arange(len(d.names))
    labelled: set[str] = set()  # each kind once in the legend, at its first closed interval
    for j, n in enumerate(d.names):
        value = abs(d.values[n]) or 1.0
        for iv, colour, dy, label in (
            (d.study_intervals.get(n), "0.5", -0.2, "study"),
            (d.after[j] if d.after else None, "C3", 0.2, "predicted with the proposal"),
        ):
            w = width(iv)
            if math.isfinite(w):
                ax.plot([iv[0] / value, iv[1] / value], [y[j] + dy] * 2, color=colour, lw=3,  # type: ignore[index]
                        label=None if label in labelled else label)  # fmt: skip
                labelled.add(label)
            elif iv is not None:
                ax.text(1.0, y[j] + dy, "open", color=colour, fontsize=8, va="center")
    ax.axvline(1.0, color="0.8", lw=0.8)
    ax.set_yticks(y, d.names)
    ax.set_xlabel("95 % interval / value")
    ax.set_title("intervals")
    if labelled:  # every interval open: nothing to name
        ax.legend(fontsize=8, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _html(d: Design, png: bytes) -> str:
    """Return ``design.html``: the report section, with ``report.html``'s tables and style."""
    from tsid_fmu.report.html_tables import CSS, esc, image, table

    part = d.section()
    body = ["<h1>Experiment design</h1>", f"<p><strong>{esc(d.verdict)}</strong></p>",
            "<ul>" + "".join(f"<li>{esc(f)}</li>" for f in part["facts"]) + "</ul>",
            table(*part["intervals"])]  # fmt: skip
    if part["separate"] is not None:
        said, columns, rows = part["separate"]
        body += [f"<p>{esc(said)}</p>", table(columns, rows)]
    body += [f"<p>{esc(sentence)}</p>" for sentence in part["structural"]]
    body.append(image(png, "the proposed input, the outputs it gives, and the intervals"))
    return (
        "<!doctype html><html><head><meta charset='utf-8'><title>tsid design</title>"
        f"<style>{CSS}</style></head><body>{''.join(body)}</body></html>"
    )


@contextlib.contextmanager
def _turn(out: Path) -> Iterator[None]:
    """Hold the lock file ``.<name>.lock`` beside ``out``: one writer at a time."""
    if fcntl is None:  # pragma: no cover
        yield
        return
    with open(out.parent / f".{out.name}.lock", "a") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(fh, fcntl.LOCK_UN)


def _files(d: Design, out: Path) -> list[Path]:
    """Write the design's files into the (new, empty) folder ``out``."""
    import pandas as pd

    files = []
    for signal, name in ((d.proposal, "design_input.csv"),
                         (d.separating, "design_structures_input.csv")):  # fmt: skip
        if signal is not None:
            frame = pd.DataFrame(signal.values, columns=d.inputs)
            frame.insert(0, "time", d.time)
            frame.to_csv(out / name, index=False)
            files.append(out / name)
    js = out / "design.json"
    js.write_text(json.dumps(d.to_dict(), indent=1, allow_nan=False), encoding="utf-8")
    md = out / "design.md"
    md.write_text(d.markdown(), encoding="utf-8")
    png = plot_design(d, out / "design.png")
    page = out / "design.html"
    page.write_text(_html(d, png.read_bytes()), encoding="utf-8")
    return [*files, png, js, md, page]


def write_design(d: Design, out: str | Path) -> list[Path]:
    """Write the design's files into ``out``; return their paths.

    ``design_input.csv`` (with a proposal), ``design_structures_input.csv`` (where the
    study's structures tied), ``design.png``, ``design.json``, ``design.md`` and
    ``design.html``. They are written into a new folder beside ``out``, which then
    replaces ``out`` as a whole (module doc): no file of an earlier design is left.

    Raises
    ------
    TypeError
        ``d`` is not a :class:`~tsid_fmu.design.Design`.
    StudyError
        ``out`` is a file, or a folder with files that are not a design's.
    """
    if not isinstance(d, Design):
        raise TypeError(f"write_design: d must be a Design (from design()), not {type(d).__name__}")
    if not isinstance(out, str | os.PathLike):
        raise TypeError(f"write_design: out must be a folder's path, not {type(out).__name__}")
    given = Path(out)
    target = check_output(given).resolve()
    new = Path(tempfile.mkdtemp(prefix=f".{target.name}.new-", dir=target.parent))
    old = None
    try:
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(new, 0o777 & ~mask)  # a folder as mkdir makes it, not mkdtemp's private one
        names = [p.name for p in _files(d, new)]
        with _turn(target):
            check_output(target)  # another writer's folder, or the user's files since
            if target.exists() or target.is_symlink():
                old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old-", dir=target.parent))
                os.replace(target, old / "design")
            os.replace(new, target)
    finally:
        if old is not None and (old / "design").exists() and not target.exists():
            with contextlib.suppress(OSError):  # failed or interrupted between the two
                os.replace(old / "design", target)  # replaces: the earlier design back
        for folder in (new, old):
            if folder is not None and folder.exists():
                shutil.rmtree(folder, ignore_errors=True)
    return [given / n for n in names]
