"""Write ``docs/reference/tuning.md``: every constant of :mod:`tsid_fmu.numerics.tuning`.

``python -m tsid_fmu.numerics.tuning_page`` prints the page; ``tests/test_tuning.py``
checks that the committed page is what it prints.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import tsid_fmu.numerics.tuning as tuning

__all__ = ["page"]

_SECTION = re.compile(r"^# -- (\S+) -+$", re.M)
_ROLE = re.compile(r":\w+:`(~?)([^`]+)`")


def _plain(text: str) -> str:
    """Return a docstring's text with Sphinx roles as Markdown code (``~`` shortens)."""
    text = _ROLE.sub(lambda m: f"`{m[2].rsplit('.', 1)[-1] if m[1] else m[2]}`", text)
    return text.replace("``", "`")


def _read_as(module: str) -> dict[str, str]:
    """Return the names under which ``module`` imports constants of the tuning module."""
    path = Path(tuning.__file__).parents[2] / Path(*module.split(".")).with_suffix(".py")
    found: dict[str, str] = {}
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and node.module == tuning.__name__:
            found |= {a.name: a.asname or a.name for a in node.names}
    return found


def page() -> str:
    """Return the Markdown page: per reading module, each constant, its value and its text."""
    source = Path(tuning.__file__).read_text(encoding="utf-8")
    parts = _SECTION.split(source)
    lines = [
        "# Reference: the tuned constants",
        "",
        "Every number that `tsid_fmu/numerics/`, `tsid_fmu/search/` and",
        "`tsid_fmu/uncertainty/` decide by, from `tsid_fmu/numerics/tuning.py`, grouped by",
        "the module that reads it. Where a text names a measurement, it is the one the value",
        "was chosen on. Written by `python -m tsid_fmu.numerics.tuning_page`; do not edit.",
    ]
    for module, body in zip(parts[1::2], parts[2::2], strict=True):
        lines += ["", f"## `{module}`", ""]
        alias = _read_as(module)
        nodes = ast.parse(body).body
        for k, node in enumerate(nodes):
            if not isinstance(node, ast.Assign):
                continue
            names = [t.id for t in node.targets if isinstance(t, ast.Name)]
            value = getattr(tuning, names[0])
            nxt = nodes[k + 1] if k + 1 < len(nodes) else None
            text = nxt.value.value if isinstance(nxt, ast.Expr) else ""
            read = [alias[n] for n in names if alias.get(n, n) != n]
            said = " = ".join(f"`{n}`" for n in names)
            lines.append(
                f"- {said} = `{value!r}`" + (f" (read as `{', '.join(read)}`)" if read else "")
            )
            for para in _plain(str(text)).strip().split("\n\n"):
                lines.append("  " + " ".join(w.strip() for w in para.split("\n")).strip())
                lines.append("")
            if lines[-1] == "":
                lines.pop()
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(page(), end="")
