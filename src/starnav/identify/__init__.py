"""Lost-in-space identification: bearing vectors in, verified catalog matches out."""

from starnav.identify.base import Identification, Identifier, IdentifyOutcome, MatchSettings
from starnav.identify.database import PairDatabase, build_database, cache_dir
from starnav.identify.pyramid import Pyramid

ALGORITHMS: dict[str, type[Identifier]] = {"pyramid": Pyramid}
DEFAULT_ALGORITHM = "pyramid"

__all__ = [
    "ALGORITHMS",
    "DEFAULT_ALGORITHM",
    "Identification",
    "Identifier",
    "IdentifyOutcome",
    "MatchSettings",
    "PairDatabase",
    "Pyramid",
    "build_database",
    "cache_dir",
]
