"""numba discrete-element method: bonded-particle breakage tests and mill-charge collisions (SI units)."""
