"""What a screening returns: indices per quantity, the parameters set apart, eq. (7)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

__all__ = ["COST", "ScreeningResult"]

COST = "cost"
"""Name of the overall cost among the screened quantities (the outputs are the others)."""


def _rank(values: dict[str, float]) -> list[str]:
    return sorted(values, key=lambda n: (-values[n], n))


@dataclass
class ScreeningResult:
    """A sensitivity screening over a study's first ranges.

    Attributes
    ----------
    method : str
        ``"morris"`` or ``"sobol"``.
    n : int
        Morris trajectories or Sobol base samples.
    parameters : list of str
        The parameters screened.
    log : dict
        Parameter -> True where it is screened in ``log10`` (as the search works).
    quantities : list of str
        ``"cost"`` (the study's cost) and each output's weighted SSE.
    indices : dict
        Quantity -> parameter -> indices (:func:`tsid_fmu.screening.indices.indices`).
    not_felt : dict
        Quantity -> the parameters below the threshold for it.
    set_apart : list of str
        Parameters not felt by the cost nor by any output.
    threshold : float
        The threshold used (fraction of the largest ``mu*``, or ``ST``).
    contribution : dict
        Quantity -> parameter -> the MISO paper's eq. (7) % from the array's runs;
        empty when it was not computed.
    contribution_set_apart : list of str
        Parameters whose eq. (7) % is below ``min_percent`` for every quantity.
    min_percent : float
        The study's ``contribution.min_percent`` (the paper's cut).
    array : str
        The array behind eq. (7) (``"L25"``), or ``""``.
    nfev : int
        Simulations run (the memo runs a repeated point once).
    nfev_screen, nfev_contribution : int
        Of which for the screening design and for the array.
    failed : int
        Points whose simulation failed; their quantities count as the largest finite
        value seen (a failure is as strong an effect as any).
    warnings : list of str
        What makes the indices less than trustworthy (too few Sobol samples).
    """

    method: str
    n: int
    parameters: list[str]
    log: dict[str, bool]
    quantities: list[str]
    indices: dict[str, dict[str, dict[str, float]]]
    not_felt: dict[str, list[str]]
    set_apart: list[str]
    threshold: float
    contribution: dict[str, dict[str, float]] = field(default_factory=dict)
    contribution_set_apart: list[str] = field(default_factory=list)
    min_percent: float = 1.0
    array: str = ""
    nfev: int = 0
    nfev_screen: int = 0
    nfev_contribution: int = 0
    failed: int = 0
    warnings: list[str] = field(default_factory=list)

    @property
    def index_name(self) -> str:
        """The index that ranks: ``mu_star_norm`` (Morris) or ``ST`` (Sobol)."""
        return "mu_star_norm" if self.method == "morris" else "ST"

    def ranking(self, quantity: str = COST) -> list[str]:
        """Return the parameters from most to least felt by ``quantity``."""
        found = self.indices[quantity]
        return _rank({n: found[n][self.index_name] for n in self.parameters})

    def contribution_ranking(self, quantity: str = COST) -> list[str]:
        """Return the parameters by decreasing eq. (7) % for ``quantity``."""
        return _rank(dict(self.contribution.get(quantity, {})))

    def to_pandas(self) -> Any:
        """Return every index as a :class:`pandas.DataFrame`, one row per quantity and parameter."""
        import pandas as pd

        rows = []
        for q in self.quantities:
            for n in self.parameters:
                row = {"quantity": q, "parameter": n, **self.indices[q][n]}
                row["not felt"] = n in self.not_felt[q]
                if self.contribution:
                    row["eq7 %"] = self.contribution[q][n]
                rows.append(row)
        return pd.DataFrame(rows).set_index(["quantity", "parameter"])

    def table(self) -> Any:
        """Return both rankings side by side, one row per parameter (most felt first).

        Columns: the ranking index and rank for the cost and each output, then eq. (7)
        and its rank for the cost, and whether each method sets the parameter apart.
        """
        import pandas as pd

        key = self.index_name
        rows = {n: {} for n in self.ranking()}
        for q in self.quantities:
            rank = {n: i + 1 for i, n in enumerate(self.ranking(q))}
            for n in rows:
                rows[n][f"{key} {q}"] = self.indices[q][n][key]
                rows[n][f"rank {q}"] = rank[n]
        if self.contribution:
            rank = {n: i + 1 for i, n in enumerate(self.contribution_ranking())}
            for n in rows:
                rows[n][f"eq7 % {COST}"] = self.contribution[COST][n]
                rows[n][f"eq7 rank {COST}"] = rank[n]
        for n in rows:
            rows[n][f"set apart ({self.method})"] = n in self.set_apart
            if self.contribution:
                rows[n]["set apart (eq7)"] = n in self.contribution_set_apart
        frame = pd.DataFrame.from_dict(rows, orient="index")
        frame.index.name = "parameter"
        return frame

    def disagreements(self) -> list[str]:
        """Return where the screening and eq. (7) disagree, one sentence each."""
        if not self.contribution:
            return []
        notes = []
        for q in self.quantities:
            # the order among parameters both methods find negligible is noise
            low = {n for n, p in self.contribution[q].items() if p < self.min_percent}
            both = low & set(self.not_felt.get(q, []))
            a = [n for n in self.ranking(q) if n not in both]
            b = [n for n in self.contribution_ranking(q) if n not in both]
            if a != b:
                moved = [f"{m} {i + 1} vs {b.index(m) + 1}" for i, m in enumerate(a) if m != b[i]]
                notes.append(f"{q}: ranks differ ({self.method} vs eq. 7): {', '.join(moved)}")
        only_s = sorted(set(self.set_apart) - set(self.contribution_set_apart))
        only_c = sorted(set(self.contribution_set_apart) - set(self.set_apart))
        if only_s:
            notes.append(f"set apart by {self.method} only: {', '.join(only_s)}")
        if only_c:
            notes.append(
                f"set apart by eq. 7 only (below {self.min_percent:g} %): {', '.join(only_c)}"
            )
        return notes

    def to_dict(self) -> dict[str, Any]:
        """Return the result as plain JSON-ready values."""
        out = asdict(self)
        out["ranking"] = {q: self.ranking(q) for q in self.quantities}
        out["disagreements"] = self.disagreements()
        return out
