"""The local search after the arrays: refinement, horizons, restarts, probes."""
