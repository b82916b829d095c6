"""Celestial positioning: latitude, longitude and heading from star cameras, gravity and UTC."""

from starnav.navigation.fix import CameraReport, Fix, FixError, fix_from_directions, locate
from starnav.navigation.observation import (
    CameraView,
    Observation,
    ObservationError,
    parse_observation,
    read_observation,
)

__all__ = [
    "CameraReport",
    "CameraView",
    "Fix",
    "FixError",
    "Observation",
    "ObservationError",
    "fix_from_directions",
    "locate",
    "parse_observation",
    "read_observation",
]
