"""In-process reference solver: 3D Euler-Bernoulli frames, scalar springs, RBE2, SPC1, GRID PS."""

from solver_adapters.reference.adapter import ReferenceAdapter

__all__ = ["ReferenceAdapter"]
