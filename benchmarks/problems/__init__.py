"""Benchmark identification problems with independent data (see ``base.py``)."""
