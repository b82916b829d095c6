"""What an observation's image file gives a camera: its detected stars (and the time it was
taken: ``starnav.detect.header.image_time``).

Stars: the image is read and its stars detected exactly as ``starnav solve IMAGE`` does
(``starnav.detect``: the same threshold and number of stars), brightest first, saturated stars
first; the centroids then go the way of a camera's ``stars`` list.
"""

from __future__ import annotations

from pathlib import Path

from starnav.detect.read import read_image
from starnav.detect.stars import Detections
from starnav.pipeline.image import detect_image


def image_stars(path: str | Path, lens: str = "pinhole") -> Detections:
    """The stars detected in an image file as ``starnav solve IMAGE`` detects them through a
    ``lens`` model (``ImageError`` for a missing or unreadable file)."""
    return detect_image(read_image(path), lens=lens)
