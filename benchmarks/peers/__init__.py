"""starnav against other solvers (cedar-solve, tetra3rs), each in its own environment."""
