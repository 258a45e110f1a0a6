"""Sensitivity screening against one identification of the same study (issue 29, item 1).

Runs ``tsid_fmu.screen`` (Morris, the default r) and ``tsid_fmu.identify`` on a study
and prints, per parameter: the screening's rank (mu* of the cost), eq. (7)'s rank from
the L25, and the rank of the final 95 % interval's width, relative to the value and in
search coordinates (over the first range's width); then the simulations of each, with
the ratio against the identification (the baseline of this run).

    python benchmarks/screening.py examples/lsea_siso/study.toml [--workers 2]
    python benchmarks/screening.py examples/lsea_miso/study.toml
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from tsid_fmu import identify
from tsid_fmu.screening import screen
from tsid_fmu.search.space import Space
from tsid_fmu.study.definition import Study


def _widths(study: Study, result) -> tuple[dict[str, float], dict[str, float]]:
    params = study.parameters
    space = Space(
        {p.name: p.levels for p in params},
        {p.name: (p.min, p.max) for p in params},
        study.method.leveling,
    )
    rel, in_s = {}, {}
    for j, name in enumerate(space.names):
        lo, hi = result.intervals.get(name) or (None, None)
        value = result.params[name]
        if lo is None or hi is None or not (math.isfinite(lo) and math.isfinite(hi)):
            rel[name] = in_s[name] = math.inf  # open: the data do not determine it
            continue
        rel[name] = (hi - lo) / abs(value)
        in_s[name] = abs(space.coordinate(j, hi) - space.coordinate(j, max(lo, 1e-300)))
    return rel, in_s


def _ranks(values: dict[str, float], largest_first: bool) -> dict[str, int]:
    order = sorted(values, key=lambda n: (-values[n] if largest_first else values[n], n))
    return {n: i + 1 for i, n in enumerate(order)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("study")
    ap.add_argument("--workers", type=int, default=None)
    args = ap.parse_args()
    study = Study.from_toml(args.study)
    t0 = time.monotonic()
    scr = screen(study, workers=args.workers)
    t1 = time.monotonic()
    res = identify(study, workers=args.workers, plots=False)
    t2 = time.monotonic()
    rel, in_s = _widths(study, res)
    morris = _ranks({n: scr.indices["cost"][n]["mu_star_norm"] for n in scr.parameters}, True)
    eq7 = _ranks(scr.contribution["cost"], True)
    narrow = _ranks(in_s, False)
    print(f"{'parameter':10} {'mu*/max':>8} {'rank':>5} {'eq7 %':>8} {'rank':>5} "
          f"{'95% width/value':>16} {'width in s':>11} {'rank':>5}")  # fmt: skip
    for n in sorted(scr.parameters, key=lambda m: morris[m]):
        print(
            f"{n:10} {scr.indices['cost'][n]['mu_star_norm']:8.3g} {morris[n]:5d} "
            f"{scr.contribution['cost'][n]:8.3g} {eq7[n]:5d} {rel[n]:16.3g} {in_s[n]:11.3g} "
            f"{narrow[n]:5d}"
        )
    same = [morris[n] == narrow[n] for n in scr.parameters]
    corr = np.corrcoef([morris[n] for n in scr.parameters], [narrow[n] for n in scr.parameters])
    print(f"\nrank agreement with the intervals: {sum(same)}/{len(same)} equal, "
          f"Spearman {corr[0, 1]:.2f}")  # fmt: skip
    print(f"set apart (morris): {scr.set_apart}; (eq. 7 < {scr.min_percent:g} %): "
          f"{scr.contribution_set_apart}")  # fmt: skip
    print(f"simulations: screening {scr.nfev} ({scr.nfev_screen} Morris r={scr.n}, "
          f"{scr.nfev_contribution} L25), identification {res.nfev} (baseline): ratio "
          f"{scr.nfev / res.nfev:.2f}; wall {t1 - t0:.0f} s vs {t2 - t1:.0f} s")  # fmt: skip


if __name__ == "__main__":
    main()
