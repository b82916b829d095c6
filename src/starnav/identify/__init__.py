"""Lost-in-space identification: bearing vectors in, verified catalog matches out.

Every algorithm is a class with ``identify(bearings, order, database, settings)``; they differ
in how they propose hypotheses and share the verification (``verify.HypothesisTester``).
Algorithms are imported when first asked for, so a table one of them needs is never built for
the others.
"""

from __future__ import annotations

from importlib import import_module

from starnav.errors import StarnavError
from starnav.identify.base import Identification, Identifier, IdentifyOutcome, MatchSettings
from starnav.identify.database import PairDatabase, build_database
from starnav.runtime.caching import cache_dir

# name -> (module, class); the order is the order of the comparison tables
ALGORITHMS: dict[str, tuple[str, str]] = {
    "pyramid": ("starnav.identify.pyramid", "Pyramid"),
    "triangle": ("starnav.identify.triangle", "Triangle"),
    "angle": ("starnav.identify.angle", "AngleMatch"),
    "voting": ("starnav.identify.voting", "GeometricVoting"),
    "neighbor-sum": ("starnav.identify.neighbor_sum", "NeighborSum"),
    "star-lines": ("starnav.identify.star_lines", "StarLines"),
    "pattern4": ("starnav.identify.pattern4", "Pattern4"),
}
DEFAULT_ALGORITHM = "pyramid"


def make_identifier(name: str, **options) -> Identifier:
    """The identifier called ``name`` (see ``ALGORITHMS``), built with ``options``."""
    if name not in ALGORITHMS:
        raise StarnavError(f"unknown algorithm {name!r}; known: {', '.join(ALGORITHMS)}")
    module, cls = ALGORITHMS[name]
    return getattr(import_module(module), cls)(**options)


__all__ = [
    "ALGORITHMS",
    "DEFAULT_ALGORITHM",
    "Identification",
    "Identifier",
    "IdentifyOutcome",
    "MatchSettings",
    "PairDatabase",
    "build_database",
    "cache_dir",
    "make_identifier",
]
