"""The Taguchi stage: orthogonal-array iterations over factors until Case 3."""
