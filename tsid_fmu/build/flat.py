"""The flattened model the Modelica build works on: its variables and their roles.

:class:`Variable` and :class:`FlatModel` are what :func:`~tsid_fmu.build.modelica.
flatten_model` returns and the code generator reads; :func:`import_build_deps` imports
the optional build dependencies (pymoca, CasADi) once, with a clear error without them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from tsid_fmu.errors import BuildError

from .expressions import Relation
from .sourcelines import SourceLines, at_line

__all__ = ["FlatModel", "Variable", "import_build_deps"]


def import_build_deps() -> tuple[Any, Any, Any, Any]:
    """Import the optional build dependencies.

    Returns
    -------
    tuple
        ``(casadi, pymoca.parser, pymoca.tree, pymoca.ast)``.

    Raises
    ------
    BuildError
        If pymoca or casadi is not installed.
    """
    try:
        import casadi
        import pymoca.ast
        import pymoca.parser
        import pymoca.tree
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise BuildError(
            f"building FMUs needs pymoca and casadi ({exc}); "
            "install them with: pip install tsid-fmu[build]"
        ) from exc
    return casadi, pymoca.parser, pymoca.tree, pymoca.ast


@dataclass
class Variable:
    """One scalar variable of the flattened model.

    Attributes
    ----------
    name : str
        Flat Modelica name.
    kind : str
        One of ``"state"``, ``"input"``, ``"output"``, ``"parameter"``, ``"local"``
        (algebraic variable that is neither input nor output).
    unit : str or None
        The ``unit`` attribute.
    description : str
        The description string of the declaration.
    start : float or None
        Start value (parameter value for parameters).
    sym : Any
        The CasADi ``SX`` symbol of the variable.
    integer : bool
        An ``Integer`` parameter (a structural switch: FMI ``Integer``/``Int32``).
    init : Any
        States only: the CasADi expression of the parameters (and constants) that gives
        the initial value, from a parameter-dependent ``start`` or an ``initial
        equation``; ``start`` is then its value at the parameters' values. ``None``:
        the initial value is ``start`` itself.
    fixed : bool
        The declaration says ``fixed = true``.
    line : int or None
        Line of the declaration in the Modelica source, where found.
    """

    name: str
    kind: str
    unit: str | None
    description: str
    start: float | None
    sym: Any = None
    integer: bool = False
    init: Any = None
    fixed: bool = False
    line: int | None = None


@dataclass
class FlatModel:
    """A flattened, scalar Modelica model ready for causalization.

    Attributes
    ----------
    name : str
        Fully qualified model name (e.g. ``"TSID.LSEA_SISO"``).
    description : str
        Description string of the model.
    source : Path
        The Modelica file the model was read from.
    states, inputs, outputs, parameters, locals : list of Variable
        Variables by role, in declaration order.
    der_syms : list
        CasADi symbols standing for ``der(state)``, in the order of ``states``.
    time : Any
        CasADi symbol of ``time``.
    residuals : list
        One CasADi ``SX`` residual ``lhs - rhs`` per equation (relations evaluated live).
    residuals_frozen : list
        The same residuals with every relation outside ``noEvent`` replaced by the
        symbol of its :class:`~.expressions.Relation` (the Model Exchange form).
    relations : list of Relation
        The relations that generate state events, in order of appearance.
    equation_text : list of str
        A readable form of each equation, for error messages.
    equation_lines : list of int or None
        The line of each equation in ``source`` (``None`` where not found).
    experiment : dict
        ``StartTime``, ``StopTime``, ``Interval`` read from ``annotation(experiment(...))``
        when present.
    info_html : str
        The ``Documentation(info=...)`` text, if any.
    lines : SourceLines or None
        Line numbers of the declarations and equations in ``source``.
    """

    name: str
    description: str
    source: Path
    states: list[Variable] = field(default_factory=list)
    inputs: list[Variable] = field(default_factory=list)
    outputs: list[Variable] = field(default_factory=list)
    parameters: list[Variable] = field(default_factory=list)
    locals: list[Variable] = field(default_factory=list)
    der_syms: list[Any] = field(default_factory=list)
    time: Any = None
    residuals: list[Any] = field(default_factory=list)
    residuals_frozen: list[Any] = field(default_factory=list)
    relations: list[Relation] = field(default_factory=list)
    equation_text: list[str] = field(default_factory=list)
    equation_lines: list[int | None] = field(default_factory=list)
    experiment: dict[str, float] = field(default_factory=dict)
    info_html: str = ""
    lines: SourceLines | None = None

    @property
    def short_name(self) -> str:
        """Last component of the qualified name (used as FMI model identifier)."""
        return self.name.rsplit(".", 1)[-1]

    @property
    def computed_states(self) -> list[Variable]:
        """The states whose initial value is computed from the parameters."""
        return [v for v in self.states if v.init is not None]

    def equation_label(self, index: int) -> str:
        """``'text'`` of equation ``index`` (0-based), with ``(line N)`` where known."""
        line = self.equation_lines[index] if index < len(self.equation_lines) else None
        return f"'{self.equation_text[index]}'" + (f" (line {line})" if line else "")

    def update_initial_starts(self) -> None:
        """Set ``start`` of each computed state to its value at the parameters' ``start``.

        Called after the parameter values changed (the build's ``start_values``).

        Raises
        ------
        BuildError
            If a computed initial value is not finite.
        """
        ca, *_ = import_build_deps()
        syms = [p.sym for p in self.parameters]
        vals = [float(p.start) for p in self.parameters]
        for v in self.computed_states:
            expr = (
                ca.substitute(ca.SX(v.init), ca.vertcat(*syms), ca.vertcat(*vals))
                if syms
                else ca.SX(v.init)
            )
            v.start = float(ca.evalf(expr))
            if not math.isfinite(v.start):
                where = at_line(f"{self.source}: model {self.name}", v.line)
                raise BuildError(
                    f"{where}: the initial value of state '{v.name}' is not finite "
                    "at the parameters' values"
                )
