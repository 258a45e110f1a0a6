"""Summarise a mutmut run: the score per file and group, and the surviving mutants.

Run from the repository root after ``mutmut run`` (``.ci/mutation`` does both)::

    python .ci/mutation_report.py                  # score table
    python .ci/mutation_report.py --survivors      # plus one line per survivor

It reads mutmut's own result files (``mutants/**/*.py.meta``) and, for each survivor,
the line that mutmut changed (``mutmut.mutation.diff_apply.get_diff_for_mutant``), so
that docs/dev/mutation-survivors.md can name each one as ``file:line`` and the change.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from collections import Counter
from pathlib import Path

STATUS = {
    1: "killed",
    3: "killed",
    0: "survived",
    33: "no tests",
    5: "no tests",
    36: "timeout",
    -24: "timeout",
    24: "timeout",
    152: "timeout",
}

GROUPS = {
    "target: interval": [
        "uncertainty/intervals.py",
        "uncertainty/profile.py",
        "uncertainty/longrun.py",
    ],
    "target: stopping": ["search/taguchi.py", "doe/rules.py", "doe/leveling.py"],
    "target: level-update": ["search/nextlevels.py"],
}


def group_of(path: str) -> str:
    """Return the group a mutated file is counted in (the target groups, else its folder)."""
    for group, files in GROUPS.items():
        if any(path.endswith(f) for f in files):
            return group
    return "other: " + path.split("/")[1]


def load() -> dict[str, dict[str, int | None]]:
    """Return each mutated file's {mutant: exit code} as mutmut left it."""
    out = {}
    for meta in sorted(Path("mutants/tsid_fmu").rglob("*.py.meta")):
        codes = json.loads(meta.read_text())["exit_code_by_key"]
        if codes:
            out[str(meta.relative_to("mutants"))[: -len(".meta")]] = codes
    return out


def status(code: int | None) -> str:
    """Return mutmut's word for an exit code (None: not run yet)."""
    return "not run" if code is None else STATUS.get(code, "suspicious")


def score_table(results: dict[str, dict[str, int | None]]) -> str:
    """Return a Markdown table: killed / run per file and group (run = all but 'not run')."""
    rows, groups = [], {}
    for path, codes in results.items():
        c = Counter(status(v) for v in codes.values())
        g = groups.setdefault(group_of(path), Counter())
        g.update(c)
        rows.append((group_of(path), path, c))
    lines = ["| group | file | killed | survived | no tests | timeout | not run | score |"]
    lines.append("|---|---|---:|---:|---:|---:|---:|---:|")

    def line(group: str, name: str, c: Counter) -> str:
        killed = c["killed"] + c["timeout"]
        run = sum(c.values()) - c["not run"]
        score = f"{100 * killed / run:.1f} %" if run else "-"
        return (
            f"| {group} | {name} | {c['killed']} | {c['survived']} | {c['no tests']} | "
            f"{c['timeout']} | {c['not run']} | {score} ({killed}/{run}) |"
        )

    for group, path, c in sorted(rows):
        lines.append(line(group, path, c))
    for group, c in sorted(groups.items()):
        lines.append(line(f"**{group}**", "all", c))
    return "\n".join(lines)


def _function_starts(path: str) -> dict[str, int]:
    """Line of each function's ``def``, by mutmut's mangled name (``x_f``, ``xǁCǁf``)."""
    tree = ast.parse(Path(path).read_text())
    starts = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            starts[f"x_{node.name}"] = node.lineno
        elif isinstance(node, ast.ClassDef):
            for sub in node.body:
                if isinstance(sub, ast.FunctionDef):
                    starts[f"x\u01c1{node.name}\u01c1{sub.name}"] = sub.lineno
    return starts


def survivors(results: dict[str, dict[str, int | None]]) -> list[tuple[str, str, str, str]]:
    """Return (mutant, file:line, original line, mutated line) of every survivor."""
    from mutmut.mutation.diff_apply import get_diff_for_mutant

    out = []
    for path, codes in results.items():
        source = Path(path).read_text().splitlines()
        starts = _function_starts(path)
        for name, code in codes.items():
            if status(code) not in ("survived", "no tests"):
                continue
            diff = get_diff_for_mutant(name, path=path).splitlines()
            func = name.rsplit(".", 1)[1].rsplit("__mutmut_", 1)[0]
            old = [d[1:] for d in diff if d.startswith("-") and not d.startswith("---")]
            new = [d[1:] for d in diff if d.startswith("+") and not d.startswith("+++")]
            line = "?"
            hunk = next((d for d in diff if d.startswith("@@")), None)
            if hunk and func in starts:
                first = int(hunk.split()[1].split(",")[0][1:])
                body = diff[diff.index(hunk) + 1 :]
                offset = next(i for i, d in enumerate(body) if d[:1] in "-+")
                line = str(starts[func] + first - 1 + offset)
                if old and source[int(line) - 1] != old[0]:
                    line = "?"
            if line == "?" and old:
                hits = [i + 1 for i, s in enumerate(source) if s == old[0]]
                line = str(hits[0]) if len(hits) == 1 else "?"
            out.append(
                (
                    name.rsplit(".", 1)[1] + f" [{status(code)}]",
                    f"{path}:{line}",
                    " / ".join(s.strip() for s in old),
                    " / ".join(s.strip() for s in new),
                )
            )
    return out


def main() -> int:
    """Print the score table and, with --survivors, one tab-separated line per survivor."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--survivors", action="store_true", help="list every survivor")
    args = parser.parse_args()
    results = load()
    if not results:
        print("no mutmut results under mutants/: run mutmut first", file=sys.stderr)
        return 1
    print(score_table(results))
    if args.survivors:
        for row in survivors(results):
            print("\t".join(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
