"""What ``tsid init`` reads into an FMU's variables and a data file's columns.

- :func:`held_reason`: why ``init`` holds a real parameter at the FMU's value rather
  than freeing it, or None: :func:`numerical_setting` (a solver step, a tolerance, a
  threshold, a regularisation), :func:`environment_constant` (a property of the medium,
  gravity, the ambient temperature or pressure) or :func:`source_time` (a ramp's start
  time, a pulse's period), each from the parameter's name, description and unit;
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

__all__ = [
    "bounded_levels",
    "decade_levels",
    "derived_hints",
    "environment_constant",
    "held_reason",
    "numerical_setting",
    "source_time",
    "time_step_setting",
]

_NAME_WORDS = frozenset(
    {"tol", "tolerance", "rtol", "atol", "reltol", "abstol", "eps", "epsilon", "threshold"}
    | {"thresh", "regularization", "regularisation", "stepsize"}
)
"""Words of a parameter's name that make it a numerical setting."""
_TIME_STEP_WORDS = frozenset({"dt", "h", "ts", "step", "timestep", "sample", "sampling"})
"""Words of a name that, with the unit ``s``, make it a time step."""
_STRONG = re.compile(
    r"\btolerances?\b|\bepsilon\b|\bregulari[sz]\w*|\bsmoothing\b|\bstep[ -]?size\b|"
    r"\btime[ -]?steps?\b|\bsolver\b|\bintegrator\b|\bnumerical(?:ly)?\b|"
    r"\bsampl(?:e|ing) (?:time|period)\b|"
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


def _leaf(name: str) -> str:
    """Return the last part of a dotted name, without an array index (``pipe.g``: ``g``)."""
    return re.sub(r"\[[^\]]*\]$", "", name).rsplit(".", 1)[-1]


def numerical_setting(v: VariableInfo) -> str | None:
    """Return why ``v`` looks like a numerical setting, or None for a physical parameter.

    A setting is a parameter of the numerics, not of the plant: a solver step or
    tolerance, the threshold below which a velocity counts as zero, a regularisation or
    smoothing constant. Identifying it fits the numerics to the noise, so ``tsid init``
    writes it commented out. The rules, conservative so that masses, stiffnesses,
    friction and damping stay free:

    - a word of the name: ``tol``, ``eps``, ``epsilon``, ``threshold``, ``rtol``, ...,
      or ``step`` followed by ``size``;
    - a time step: ``dt``, ``h``, ``Ts``, ``step``, ``timestep``, ``sample`` in the last
      part of the name, with unit ``s`` (Hopsan's ``timestep``; not ``step.startTime``,
      a Step source's start time);
    - a tool's internal setting: the last part of its name starts with ``_``
      (JModelica.org's ``_cs_rel_tol``, ``_nle_solver_max_residual_scaling_factor``);
    - the description says tolerance, epsilon, regularisation, smoothing, step size,
      time step, solver, integrator, numerical, sampling time or scaling (OpenModelica's
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
    if v.unit == "s" and any(w in _TIME_STEP_WORDS for w in _words(_leaf(v.name))):
        return "a time step (its name, unit s)"
    text = v.description or ""
    found = _STRONG.search(text)
    if found is None and not _PHYSICAL.search(text):
        found = _WEAK.search(text)
    if found is not None:
        return f"its description says {found.group(0)!r}"
    return None


_STEP_WORDS = frozenset({"dt", "h", "timestep", "stepsize"})
"""Words, or two words joined, of a name's last part that, with the unit ``s``, make it an
integration step (not ``Ts`` or ``sample``: a sampled controller's period is part of its
behaviour; not ``stepTime``: a step source's)."""
_STEP_TEXT = re.compile(
    r"\bstep[ -]?size\b|\btime[ -]?steps?\b|\bintegrat\w* step\b|\binternal step\b",
    re.IGNORECASE,
)
"""Words of a description that, with the unit ``s``, make a parameter an integration step."""


def time_step_setting(v: VariableInfo) -> bool:
    """Return whether ``v`` is the FMU's own integration time step, a parameter in s.

    Hopsan's ``timestep``, a generated FMU's ``fixedStepSize``: a Co-Simulation FMU that
    integrates on a grid of its own ignores the communication step and the tolerance,
    so the solver-fidelity check's reference also runs it at a smaller one. A word of
    the last part of the name (``dt``, ``h``, ``timestep``, ``stepSize``, or ``step``
    alone) or the description (step size, time step, integration step, internal step),
    with the unit ``s``.
    """
    if v.causality != "parameter" or v.unit != "s":
        return False
    words = _words(_leaf(v.name))
    joined = {a + b for a, b in itertools.pairwise(words)}
    if words == ["step"] or not _STEP_WORDS.isdisjoint({*words, *joined}):
        return True
    return _STEP_TEXT.search(v.description or "") is not None


_WORLD_PARTS = frozenset({"medium", "system", "ambient", "environment", "world"})
"""Components of a name's path (before its last part) that hold the environment:
Modelica.Fluid's ``system``, MultiBody's ``world``, a ``medium`` record."""
_WORLD_WORDS = frozenset({"ambient", "amb", "environment"})
"""Words of a name's last part that name the environment (``p_ambient``, ``T_amb``)."""
_GRAVITY_UNITS = frozenset({"m/s2", "m/s^2", "m.s-2", "m/(s2)", "m/(s.s)"})
"""Units of an acceleration, which make a parameter named ``g`` gravity."""
_WORLD_TEXT = re.compile(
    r"\bmedi(?:um|a)\b|\bambient\b|\benvironment(?:al)?\b|\bgravit(?:y|ational)\b|"
    r"\breference temperature\b|\btemperature coefficient\b|\bdevice temperature\b",
    re.IGNORECASE,
)
"""Words of a description that make a parameter a constant of the medium or the world
(Dymola's ``resistor.T_ref`` "Reference temperature", ``resistor.alpha`` "Temperature
coefficient of resistance", ``resistor.T`` "Fixed device temperature ...")."""
_PLANT_TEXT = re.compile(
    r"\bbetween\b|\bwall\b|\bheat transfer\b|\bconductance\b|\bvolume\b|\barea\b|"
    r"\blength\b|\bdiameter\b|\bradius\b|\bheight\b|\bcent(?:er|re) of gravity\b",
    re.IGNORECASE,
)
"""Words of a description that keep it a plant's parameter although it names the medium
or the ambient ("heat transfer coefficient between wall and medium", "thermal
conductance to ambient", "volume of medium in the tank", "centre of gravity")."""


def environment_constant(v: VariableInfo) -> str | None:
    """Return why ``v`` looks like a constant of the medium or the environment, or None.

    Gravity, the ambient pressure and temperature, a medium's density or a resistor's
    reference temperature act on the plant, but a test rig's data do not decide them
    (they are known, or trade with a plant parameter: a resistor's ``alpha`` acts only
    through ``R * (1 + alpha * (T - T_ref))``); freed, they move the model outside the
    medium's range ("Temperature outside scope of model!"). The rules:

    - a component of the name's path: ``medium``, ``system``, ``ambient``,
      ``environment``, ``world`` (Modelica.Fluid's ``system.p_ambient``, MultiBody's
      ``world.g``);
    - a word of the last part: ``ambient``, ``amb``, ``environment`` (``p_ambient``,
      ``T_amb``);
    - the last part ``g`` with the unit of an acceleration (``pipe.g``, unit ``m/s2``);
    - the description says medium, ambient, environment, gravity, reference
      temperature, temperature coefficient or device temperature, unless it also names
      the plant's geometry or a transfer (between, wall, heat transfer, conductance,
      volume, area, length, diameter, radius, height, centre of gravity); gravity only
      with the unit of an acceleration, or none: a pendulum's "Gravity torque at 90
      degrees (m g l)" in N.m is the plant's.
    """
    parts = [re.sub(r"\[[^\]]*\]|\d+$", "", p).lower() for p in v.name.split(".")[:-1]]
    hit = next((p for p in parts if p in _WORLD_PARTS), None)
    if hit is not None:
        return f"its name's path holds {hit!r}"
    leaf = _leaf(v.name)
    word = next((w for w in _words(leaf) if w in _WORLD_WORDS), None)
    if word is not None:
        return f"its name says {word!r}"
    unit = (v.unit or "").replace(" ", "")
    if leaf == "g" and unit in _GRAVITY_UNITS:
        return f"g in {v.unit}: gravity"
    text = v.description or ""
    found = _WORLD_TEXT.search(text)
    if found is None or _PLANT_TEXT.search(text):
        return None
    if found.group(0).lower().startswith("gravit") and unit and unit not in _GRAVITY_UNITS:
        return None  # a quantity gravity acts through ("gravity torque m g l", N.m)
    return f"its description says {found.group(0)!r}"


_SOURCE_TIME_WORDS = frozenset({"starttime", "duration", "period", "offset"})
"""Last parts of a name (lower case, ``_`` removed) that, with the unit ``s``, make it a
source's time (Modelica.Blocks.Sources' ``ramp.startTime``, ``ramp.duration``,
``pulse.period``, ``step.startTime``)."""
_SOURCE_TEXT = re.compile(
    r"\bstart(?:ing)? time\b|\bfor time < ?\w+|\bduration of (?:the )?"
    r"(?:ramp|step|pulse|signal|source|input)\b|\btime for one period\b|"
    r"\b(?:delay|start) of (?:the )?(?:ramp|step|pulse|signal|source|input)\b",
    re.IGNORECASE,
)
"""Words of a description that make a parameter in seconds a source's time (MSL's
"Output y = offset for time < startTime", "Duration of ramp (= 0.0 gives a Step)",
"Time for one period")."""


def source_time(v: VariableInfo) -> str | None:
    """Return why ``v`` looks like the time of a signal source's event, or None.

    A ramp's start time and duration, a step's start time, a pulse's period set when
    the model's own input moves: a setting of the experiment, which the data record
    rather than decide (freed, the levels move the input away from the measured one).
    The rules, for a parameter in seconds (or without a unit, for the description):

    - the last part of the name is ``startTime``, ``start_time``, ``duration``,
      ``period`` or ``offset``, with unit ``s``;
    - the description says start time, "for time < ...", "duration of ramp" (step,
      pulse, signal, source, input), "time for one period", "delay of" or "start of" a
      ramp (step, ...).

    A time constant, a delay time of the plant or a period of a plant's oscillation
    stays free.
    """
    if v.unit not in ("s", None, ""):
        return None
    leaf = _leaf(v.name)
    if v.unit == "s" and leaf.replace("_", "").lower() in _SOURCE_TIME_WORDS:
        return f"its name says {leaf!r}, unit s"
    found = _SOURCE_TEXT.search(v.description or "")
    if found is not None:
        return f"its description says {found.group(0)!r}"
    return None


def held_reason(v: VariableInfo) -> str | None:
    """Return why ``tsid init`` holds ``v`` at the FMU's value, or None to free it.

    One reason, the first that applies: a numerical setting
    (:func:`numerical_setting`), a constant of the medium or the environment
    (:func:`environment_constant`), a signal source's time (:func:`source_time`). The
    reason is written beside the parameter's entry, which is commented out.
    """
    reason = numerical_setting(v)
    if reason is not None:
        return f"numerical, not physical ({reason})"
    reason = environment_constant(v)
    if reason is not None:
        return f"a constant of the medium or the environment ({reason})"
    reason = source_time(v)
    if reason is not None:
        return f"a setting of a signal source (its time), not a parameter of the plant ({reason})"
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
