"""What ``tsid init`` reads into an FMU's variables and a data file's columns.

- :func:`numerical_setting`: whether a real parameter is a numerical setting (a solver
  step, a tolerance, a threshold, a regularisation) rather than a physical parameter,
  from its name, description and unit;
- :func:`bounded_levels`: five levels around the start value inside the bounds that the
  FMU declares;
- :func:`derived_hints`: for an FMU input or output without a column, the columns that
  look like it once combined (``F_o = F_of - F_or``) or differentiated
  (``v_o = der(x_o)``).
"""

from __future__ import annotations

import itertools
import keyword
import math
import re
from collections.abc import Mapping, Sequence

from tsid_fmu.fmu.variables import VariableInfo

__all__ = ["bounded_levels", "decade_levels", "derived_hints", "numerical_setting"]

_NAME_WORDS = frozenset(
    {"tol", "tolerance", "rtol", "atol", "reltol", "abstol", "eps", "epsilon", "threshold"}
    | {"thresh", "regularization", "regularisation", "stepsize"}
)
"""Words of a parameter's name that make it a numerical setting."""
_TIME_STEP_WORDS = frozenset({"dt", "h", "ts", "step", "sample", "sampling"})
"""Words of a name that, with the unit ``s``, make it a time step."""
_STRONG = re.compile(
    r"\btolerances?\b|\bepsilon\b|\bregulari[sz]\w*|\bsmoothing\b|\bstep[ -]?size\b|"
    r"\bsolver\b|\bintegrator\b|\bnumerical(?:ly)?\b|\bsampl(?:e|ing) (?:time|period)\b|"
    r"\b(?:used )?for scaling\b|\bscaling (?:factor|nominal)\b",
    re.IGNORECASE,
)
"""Words of a description that make a parameter a numerical setting."""
_WEAK = re.compile(
    r"\bthreshold\b|\b(?:below|above|under|over) which\b[^.;]*?\b(?:considered|treated|"
    r"assumed|regarded|taken)\b(?: (?:to be |as )?(?:at rest|zero|stopped|stuck|static))?|"
    r"\bconsidered (?:to be )?(?:at rest|zero|stopped|stuck|static)\b",
    re.IGNORECASE,
)
"""Words of a description that make a parameter numerical unless it names physics."""
_PHYSICAL = re.compile(
    r"\b(?:mass|masses|inertia|stiffness|spring constant|damping|friction|viscous|coulomb|"
    r"resistance|inductance|capacitance|conductivity|permittivity|density|radius|length|"
    r"area|volume)\b",
    re.IGNORECASE,
)
"""Words of a description that keep a threshold-like parameter physical."""


def _words(name: str) -> list[str]:
    """Split ``fixedStepSize``, ``V_z``, ``relTol2`` into lower-case words."""
    return [w.lower() for w in re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+|\d+", name)]


def numerical_setting(v: VariableInfo) -> str | None:
    """Return why ``v`` looks like a numerical setting, or None for a physical parameter.

    A setting is a parameter of the numerics, not of the plant: a solver step or
    tolerance, the threshold below which a velocity counts as zero, a regularisation or
    smoothing constant. Identifying it fits the numerics to the noise, so ``tsid init``
    writes it commented out. The rules, conservative so that masses, stiffnesses,
    friction and damping stay free:

    - a word of the name: ``tol``, ``eps``, ``epsilon``, ``threshold``, ``rtol``, ...,
      or ``step`` followed by ``size``;
    - a time step: ``dt``, ``h``, ``Ts``, ``step``, ``sample`` in the name, with unit ``s``;
    - a tool's internal setting: the last part of its name starts with ``_``
      (JModelica.org's ``_cs_rel_tol``, ``_nle_solver_max_residual_scaling_factor``);
    - the description says tolerance, epsilon, regularisation, smoothing, step size,
      solver, integrator, numerical, sampling time or scaling (OpenModelica's
      ``damper.s_nominal``, "Nominal value of s_rel (used for scaling)");
    - the description says threshold, or "below which ... is considered ...", "considered
      at rest", unless it also names a physical property (mass, stiffness, friction,
      damping, ...).
    """
    if v.name.rsplit(".", 1)[-1].startswith("_"):
        return "a tool's internal setting (its name starts with '_')"
    words = _words(v.name)
    joined = {a + b for a, b in itertools.pairwise(words)}
    hit = next((w for w in words if w in _NAME_WORDS), None) or (
        "stepsize" if "stepsize" in joined else None
    )
    if hit is not None:
        return f"its name says {hit!r}"
    if v.unit == "s" and any(w in _TIME_STEP_WORDS for w in words):
        return "a time step (its name, unit s)"
    text = v.description or ""
    found = _STRONG.search(text)
    if found is None and not _PHYSICAL.search(text):
        found = _WEAK.search(text)
    if found is not None:
        return f"its description says {found.group(0)!r}"
    return None


def decade_levels(start: float, n: int = 5) -> list[float]:
    """Return ``n`` levels log-spaced over one decade around ``start`` (4 figures).

    A start value of zero gives ``n`` levels from -1 to 1.
    """
    if start == 0 or not math.isfinite(start):
        return [round(-1 + 2 * k / (n - 1), 6) for k in range(n)]
    mag = abs(start)
    values = [float(f"{mag * 10 ** (-0.5 + k / (n - 1)):.4g}") for k in range(n)]
    return values if start > 0 else sorted(-v for v in values)


def bounded_levels(
    start: float, low: float | None = None, high: float | None = None, n: int = 5
) -> list[float]:
    """Return :func:`decade_levels` of ``start``, kept inside ``[low, high]``.

    Levels that the bounds cut off are replaced: the start value (moved inside the
    bounds if need be) stays the middle level and the others are log-spaced (linearly
    spaced around zero) from it to the decade's end or the bound, whichever is nearer.
    A restitution coefficient ``e = 0.7`` in ``[0.5, 1]`` gets ``0.5 ... 1``, not
    ``0.22 ... 2.2``.
    """
    lo = -math.inf if low is None else low
    hi = math.inf if high is None else high
    levels = decade_levels(start, n)
    if all(lo <= v <= hi for v in levels) or not lo < hi:
        return levels
    s = min(max(start if math.isfinite(start) else 0.0, lo), hi)
    if s < 0:
        return sorted(-v for v in bounded_levels(-s, -hi, -lo, n))
    if s == 0:
        a, b = max(-1.0, lo), min(1.0, hi)
        raw = [a + (b - a) * k / (n - 1) for k in range(n)]
    else:
        a, b = max(s / math.sqrt(10), lo), min(s * math.sqrt(10), hi)
        m = (n - 1) // 2
        if a < s < b:
            raw = [a * (s / a) ** (k / m) for k in range(m)]
            raw += [s * (b / s) ** (k / (n - 1 - m)) for k in range(n - m)]
        else:
            raw = [a * (b / a) ** (k / (n - 1)) for k in range(n)]
    for digits in (4, 6, 9, 17):
        out = sorted({min(max(float(f"{x:.{digits}g}"), lo), hi) for x in raw})
        if len(out) == n:
            return out
    return sorted(set(raw))


_RATE = {"v": 1, "vel": 1, "velocity": 1, "a": 2, "acc": 2, "accel": 2, "acceleration": 2}
_ANGULAR_RATE = {"w": 1, "omega": 1, "alpha": 2}
_POSITION = ("x", "s", "p", "pos", "position", "q")
_ANGLE = ("phi", "theta", "q", "angle")


def _derivative_of(name: str, columns: Mapping[str, str]) -> str | None:
    """``der(...)`` of a column for a velocity or acceleration ``name``, or None."""
    m = re.fullmatch(r"der\((\w+)\)|(\w+?)_?(d{1,2})ot", name)
    if m is not None:
        base, order = (m.group(1), 1) if m.group(1) else (m.group(2), len(m.group(3)))
        if order == 2 and f"{base}_dot".lower() in columns:
            return f"der({columns[f'{base}_dot'.lower()]})"
        col = columns.get(base.lower())
        return None if col is None else (f"der({col})" if order == 1 else f"der({col}, 2)")
    head, sep, rest = name.partition("_")
    order = _RATE.get(head.lower()) or _ANGULAR_RATE.get(head.lower())
    if order is None or not sep:
        return None
    if order == 2 and head.lower() in _RATE and f"v_{rest}".lower() in columns:
        return f"der({columns[f'v_{rest}'.lower()]})"
    for base in _ANGLE if head.lower() in _ANGULAR_RATE else _POSITION:
        col = columns.get(f"{base}_{rest}".lower())
        if col is not None:
            return f"der({col})" if order == 1 else f"der({col}, 2)"
    return None


def derived_hints(
    missing: Sequence[str], columns: Sequence[str], unused: Sequence[str] | None = None
) -> dict[str, str]:
    """Return an expression of the columns for each FMU variable in ``missing`` that has one.

    A variable ``F_o`` (two characters or more) whose name begins one unused column
    (``F_o_meas``) or two
    (``F_of``, ``F_or``: two one-sided load cells) gets that column or their difference; a
    velocity or acceleration (``v_o``, ``a_o``, ``w_j``, ``x_dot``, ``der(x)``) whose
    position has a column (``x_o``, ``phi_j``, ``x``) gets its derivative. Only columns
    that an expression can name (Python identifiers) are used; names compare
    case-insensitively.

    Parameters
    ----------
    missing : sequence of str
        FMU inputs and outputs without a column.
    columns : sequence of str
        The data's columns (without time).
    unused : sequence of str, optional
        The columns no FMU variable is mapped to (default: all).
    """
    usable = [c for c in columns if c.isidentifier() and not keyword.iskeyword(c)]
    free = [c for c in usable if unused is None or c in unused]
    by_lower = {c.lower(): c for c in usable}
    hints: dict[str, str] = {}
    for name in missing:
        parts = [c for c in free if c.lower().startswith(name.lower()) and len(c) > len(name)]
        parts = parts if len(name) > 1 else []  # "F" begins too many names to tell
        if len(parts) == 1:
            hints[name] = parts[0]
        elif len(parts) == 2:
            hints[name] = f"{parts[0]} - {parts[1]}"
        else:
            expression = _derivative_of(name, by_lower)
            if expression is not None:
                hints[name] = expression
    return hints
