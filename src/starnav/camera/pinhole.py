"""Pinhole camera with radial distortion: the first ``CameraModel``.

Pixels: x right, y down, origin at the top-left corner of the image (the top-left pixel's
centre is (0.5, 0.5)). Camera frame: x right, y down, z along the boresight.

Parity is not a camera property here: a mirrored image is described by an attitude matrix with
determinant -1 (see ``starnav.geometry``), so the projection is the same for both. Radial
distortion: (u, v) -> (u, v) (1 + k1 r^2 + k2 r^4) on the normalised radius r. The arithmetic
is in ``camera.kernels`` (shared with the attitude fit and the verification).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from starnav.camera.lens import Lens, check_size
from starnav.errors import CameraError, shown


def focal_px_from_fov(fov_deg: float, width: int) -> float:
    """Focal length in pixels for a horizontal field of view (degrees) across ``width`` px."""
    return 0.5 * width / np.tan(0.5 * np.radians(fov_deg))


@dataclass(frozen=True)
class Camera(Lens):
    """Pinhole camera with optional radial distortion.

    Attributes: ``width``, ``height`` (px); ``focal_px``; principal point ``cx``, ``cy`` (px,
    default the image centre); ``k1``, ``k2`` radial distortion coefficients (dimensionless).
    """

    width: int
    height: int
    focal_px: float
    cx: float | None = None
    cy: float | None = None
    k1: float = 0.0
    k2: float = 0.0

    model = "pinhole"
    model_code = 0  # camera.kernels.PINHOLE
    coefficients = ("k1", "k2")  # the model's coefficients, in the order of ``params``
    kind = "pinhole"
    scans_focal = False  # an unknown field of view: the FOV search (4-star patterns)
    default_fov_range_deg = (5.0, 40.0)
    # then a wide-angle or phone photograph's, then a long lens's or a telescope's: a 45-55°
    # phone frame is solved without a --fov-range, in the time the default range left
    # (searching 3-70° at once took twice the time on the frames the default holds, and lost
    # one to the budget); 0.625-5° in one search (its bands' patterns breadth first, the bands
    # under ~5° across cut from the embedded Gaia DR3), so that 40-70° keeps half of what
    # the default range left
    extended_fov_ranges_deg = ((40.0, 70.0), (0.625, 5.0))
    # the narrowest field searched: 0.625° along the image's longer side (a portrait image's
    # height: pipeline.fov.fov_limits_deg), the foot of the band grid's 0.884° table, so that
    # one Gaia table (44 s to build, 120 MB in memory) reaches it: the embedded Gaia DR3
    # (G <= 10) holds about 3 stars in a 0.625° x 0.42° field on average, 15-30 in open
    # clusters and the Milky Way's dense fields, which telescopes often frame
    fov_limits_deg = (0.625, 100.0)
    fits_projection = "TAN"  # TAN-SIP with distortion
    sip_max_order = 7

    def __post_init__(self) -> None:
        check_size(self.width, self.height, self.focal_px)
        self._centre_and_params([self.k1, self.k2])

    @classmethod
    def from_fov(cls, fov_deg: float, width: int, height: int | None = None) -> Camera:
        """Camera whose horizontal field of view across ``width`` px is ``fov_deg`` degrees."""
        if not (np.isfinite(fov_deg) and 0.0 < fov_deg < 179.0):
            raise CameraError(
                f"fov_deg must be above 0 and below 179 degrees, got {shown(fov_deg)}"
            )
        if not (np.isfinite(width) and width >= 8):
            raise CameraError(f"width must be at least 8 px, got {shown(width)}")
        height = width if height is None else height
        if not (np.isfinite(height) and height >= 8):
            raise CameraError(f"height must be at least 8 px, got {shown(height)}")
        return cls(int(width), int(height), focal_px_from_fov(fov_deg, width))

    @property
    def fov_deg(self) -> float:
        """Horizontal field of view in degrees."""
        return math.degrees(2.0 * math.atan(0.5 * self.width / self.focal_px))

    @property
    def scale_px_per_rad(self) -> float:
        """Pixels per radian the tolerances divide by: the focal length (the pinhole is
        finest at its centre; its distortion is taken as small)."""
        return self.focal_px

    def check_monotonic(self, where: str) -> None:
        """As ``Lens.check_monotonic``, only for a distorted pinhole."""
        if self.distorted:
            super().check_monotonic(where)
