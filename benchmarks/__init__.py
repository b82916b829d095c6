"""starnav's benchmarks: scripts whose output is committed under docs/ (benchmarks/README.md
lists them); ``harness`` is what they share. Not part of the installed package."""
