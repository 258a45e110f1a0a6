"""Structure identification: mixed arrays, candidate structures, nesting, selection."""
