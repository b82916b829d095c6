"""Fisheye lens models: the image radius a function of the angle from the optical axis.

A direction at angle θ from the axis with camera-frame azimuth φ lands at pixel
(cx + r cos φ, cy + r sin φ) (x right, y down, origin at the top-left corner), with

- ``equidistant``:     r = f θ
- ``equisolid``:       r = 2 f sin(θ/2)
- ``stereographic``:   r = 2 f tan(θ/2)
- ``orthographic``:    r = f sin θ            (θ up to 90°)
- ``kannala-brandt``:  r = f θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)   (OpenCV's fisheye model)

θ may pass 90°: a 190° lens sees 5° behind its image plane. ``image_circle_deg`` is the full
angle of the lens's image circle when it is smaller than the image (a circular fisheye);
directions outside it are not seen. The arithmetic is in ``camera.kernels``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from starnav.camera.lens import Lens, check_size, kernels
from starnav.errors import CameraError, shown


@dataclass(frozen=True)
class Fisheye(Lens):
    """A fisheye camera. ``width``, ``height`` (px); ``focal_px`` (px per radian at the
    centre); principal point ``cx``, ``cy`` (px, default the image centre);
    ``image_circle_deg``: full angle of the image circle (degrees; None: the whole image)."""

    width: int
    height: int
    focal_px: float
    cx: float | None = None
    cy: float | None = None
    image_circle_deg: float | None = None

    kind = "fisheye"
    scans_focal = True  # an unknown focal length: the focal scan
    default_fov_range_deg = (100.0, 200.0)
    fov_limits_deg = (10.0, 360.0)
    # a fisheye's distortion over up to 95° from the axis needs more terms than a pinhole's
    # over its narrower field: choose_sip_order may go to the highest order for it
    sip_max_order = 9

    def __post_init__(self) -> None:
        check_size(self.width, self.height, self.focal_px)
        for name in self.coefficients:
            value = getattr(self, name)
            if not np.isfinite(value):
                raise CameraError(f"{name} must be finite, got {shown(value)}")
        circle = self.image_circle_deg
        if circle is not None and not (np.isfinite(circle) and 0.0 < circle <= 360.0):
            raise CameraError(f"image_circle_deg must be in (0, 360], got {shown(circle)}")
        limit = math.pi if circle is None else math.radians(0.5 * circle)
        coefficients = [getattr(self, name) for name in self.coefficients]
        self._centre_and_params([*coefficients, *[0.0] * (4 - len(coefficients)), limit])

    @classmethod
    def from_params(cls, width: int, height: int, params: np.ndarray):
        """The camera of a kernel parameter vector (focal_px, cx, cy, k1..k4, θ limit)."""
        camera = super().from_params(width, height, params)
        if len(params) > 7 and params[7] < math.pi:
            camera = camera.with_circle(math.degrees(2.0 * params[7]))
        return camera

    def with_circle(self, image_circle_deg: float | None):
        """The same camera with another image circle."""
        return dataclasses.replace(self, image_circle_deg=image_circle_deg)

    @classmethod
    def from_fov(cls, fov_deg: float, width: int, height: int | None = None, **coefficients):
        """The camera whose horizontal field across ``width`` px is ``fov_deg`` degrees
        (``coefficients``: the model's, e.g. k1..k4 of Kannala-Brandt)."""
        top = 2.0 * math.degrees(kernels().model_theta_max(cls.model_code))
        if not (np.isfinite(fov_deg) and 0.0 < fov_deg <= top):
            raise CameraError(
                f"fov_deg must be above 0 and at most {top:.0f} degrees for the {cls.model} "
                f"model, got {shown(fov_deg)}"
            )
        height = width if height is None else height
        unit = cls(int(width), int(height), 1.0, **coefficients)
        return cls(
            int(width), int(height), unit.focal_for_radius(0.5 * width, fov_deg), **coefficients
        )

    def focal_for_radius(self, radius_px: float, field_deg: float) -> float:
        """The focal length (px) at which this model's circle of ``radius_px`` about the
        principal point spans ``field_deg`` degrees (e.g. an image circle's 180°), cut at the
        widest field the model maps."""
        top = 2.0 * math.degrees(self.model_theta_max_rad)
        theta = math.radians(0.5 * min(field_deg, top))
        g, _ = kernels().radial_g(self.model_code, self.params, theta)
        return float(radius_px / g)

    def with_centre(self, cx: float, cy: float):
        """The same camera with its principal point at (``cx``, ``cy``) px."""
        return dataclasses.replace(self, cx=float(cx), cy=float(cy))

    @property
    def fov_deg(self) -> float:
        """Horizontal field of view in degrees (the angle across the image's width through
        the principal point, as if centred)."""
        theta = kernels().radial_theta(
            self.model_code, self.params, 0.5 * self.width / self.focal_px
        )
        return float(math.degrees(2.0 * theta))

    def file_keys(self) -> tuple[str, ...]:
        """The keys of this model's camera file, besides ``model``."""
        keys = super().file_keys()
        return keys if self.image_circle_deg is None else (*keys, "image_circle_deg")

    @classmethod
    def optional_values(cls, data: dict, where: str) -> dict:
        """``image_circle_deg`` when the camera file gives it."""
        if "image_circle_deg" not in data:
            return {}
        value = data["image_circle_deg"]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CameraError(f"{where}: image_circle_deg must be a number, got {value!r}")
        return {"image_circle_deg": float(value)}


class Equidistant(Fisheye):
    """r = f θ: equal steps of angle are equal steps of radius."""

    model = "equidistant"
    model_code = 1  # camera.kernels.EQUIDISTANT
    fits_projection = "ARC"


class Equisolid(Fisheye):
    """r = 2 f sin(θ/2): equal areas of sky are equal areas of image."""

    model = "equisolid"
    model_code = 2  # camera.kernels.EQUISOLID
    fits_projection = "ZEA"


class Stereographic(Fisheye):
    """r = 2 f tan(θ/2): shapes are kept (conformal)."""

    model = "stereographic"
    model_code = 3  # camera.kernels.STEREOGRAPHIC
    fits_projection = "STG"


class Orthographic(Fisheye):
    """r = f sin θ, up to 90° from the axis."""

    model = "orthographic"
    model_code = 4  # camera.kernels.ORTHOGRAPHIC
    fits_projection = "SIN"


@dataclass(frozen=True)
class KannalaBrandt(Fisheye):
    """r = f θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸), θ in radians (OpenCV's fisheye)."""

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    k4: float = 0.0

    model = "kannala-brandt"
    model_code = 5  # camera.kernels.KANNALA_BRANDT
    coefficients = ("k1", "k2", "k3", "k4")
    fits_projection = "ARC"  # that of its coefficients at zero (equidistant), ARC-SIP with them
