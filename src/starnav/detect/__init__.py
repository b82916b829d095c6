"""Image files to star centroids: reading, background, detection, sub-pixel centroids."""

from starnav.detect.read import read_image
from starnav.detect.stars import Detections, detect_stars

__all__ = ["Detections", "detect_stars", "read_image"]
