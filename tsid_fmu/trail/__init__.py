"""The audit trail: every iteration and stage on disk as it ends, and resuming from it."""

from tsid_fmu.trail.files import atomic_write, read_json, strict, write_json
from tsid_fmu.trail.folder import NullStore, Trail
from tsid_fmu.trail.levels import read_next_levels, write_next_levels

__all__ = [
    "NullStore",
    "Trail",
    "atomic_write",
    "read_json",
    "read_next_levels",
    "strict",
    "write_json",
    "write_next_levels",
]
