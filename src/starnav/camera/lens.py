"""What every lens model shares: the kernel calls, the checks, the camera-file form.

A model class is a frozen dataclass with the fields ``width``, ``height`` (px),
``focal_px``, ``cx``, ``cy`` (px), then its coefficients (named in ``coefficients``), and
the class attributes of its facts (``Lens``: its name in camera files, its branch of
``camera.kernels``, its kind, how an unknown focal length is found, its field-of-view range
and limits, its FITS projection and SIP order), which the rest of starnav asks instead of
comparing model names. ``Lens`` gives it the projection both ways, the field it covers, the
angular scale the tolerances use, the parameter vector of the kernels and the camera file.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import ClassVar

import numpy as np

from starnav.errors import CameraError, shown

_SCALE_SAMPLES = 64  # angles from the axis at which the angular scale is taken
_MONOTONIC_SAMPLES = 4096  # angles at which a camera file's r(θ) is checked to increase
MIN_SCALE_FRACTION = 0.25  # the tolerances' scale never drops below this part of f


def kernels():
    from starnav.camera import kernels  # numba: loaded when a projection is first needed

    return kernels


def check_size(width: float, height: float, focal_px: float) -> None:
    """One-line errors for an image size or focal length that cannot be."""
    for name, value in (("width", width), ("height", height)):
        if not (np.isfinite(value) and value > 0):
            raise CameraError(f"{name} must be a positive number of pixels, got {shown(value)}")
    if not (np.isfinite(focal_px) and focal_px > 0):
        raise CameraError(f"focal_px must be positive, got {shown(focal_px)}")


KINDS = ("pinhole", "fisheye")  # the values of ``Lens.kind``


class Lens:
    """Methods every lens model has (mixed into its frozen dataclass), and the facts each
    model class declares (``camera.model.register_model`` checks them):

    - ``model``: its name in camera files (the key of ``camera.MODELS``);
    - ``model_code``: its branch of the ``camera.kernels`` projections;
    - ``coefficients``: the names of its distortion coefficients, in the order of ``params``;
    - ``kind``: ``"pinhole"`` (a perspective lens: it sees in front of its image plane only
      and images its whole sensor) or ``"fisheye"`` (θ from the axis may pass 90°, an image
      circle may lie on the sensor: detection looks inside it, the renderer vignettes);
    - ``scans_focal``: whether an unknown focal length is scanned (``pipeline.fov``'s focal
      scan) rather than searched with 4-star patterns matched up to a scale (the FOV search);
    - ``default_fov_range_deg``: the horizontal field (degrees) searched when none is given;
    - ``extended_fov_ranges_deg``: the ranges searched after that one, in order, while the
      time budget lasts, when the default found nothing (none: the default only);
    - ``fov_limits_deg``: the horizontal fields (degrees) a search or a given field may take;
    - ``fits_projection``: the FITS zenithal projection (CTYPE suffix) whose radius is the
      model's with its coefficients at zero (``undistorted``); SIP polynomials take the rest;
    - ``sip_max_order``: the highest SIP order ``output.wcs.choose_sip_order`` goes to.
    """

    width: int
    height: int
    focal_px: float
    cx: float
    cy: float
    params: np.ndarray
    model: ClassVar[str] = ""
    model_code: ClassVar[int] = -1
    coefficients: ClassVar[tuple[str, ...]] = ()
    kind: ClassVar[str] = ""
    scans_focal: ClassVar[bool] = False
    default_fov_range_deg: ClassVar[tuple[float, float]] = (0.0, 0.0)
    extended_fov_ranges_deg: ClassVar[tuple[tuple[float, float], ...]] = ()
    fov_limits_deg: ClassVar[tuple[float, float]] = (0.0, 0.0)
    fits_projection: ClassVar[str] = ""
    sip_max_order: ClassVar[int] = 0

    def _centre_and_params(self, params: list[float]) -> None:
        """Fill in the default principal point (the image centre) and ``params``."""
        if self.cx is None:
            object.__setattr__(self, "cx", self.width / 2.0)
        if self.cy is None:
            object.__setattr__(self, "cy", self.height / 2.0)
        vector = [self.focal_px, self.cx, self.cy, *params]
        object.__setattr__(self, "params", np.array(vector, dtype=np.float64))

    @classmethod
    def from_params(cls, width: int, height: int, params: np.ndarray):
        """The camera of a kernel parameter vector (focal_px, cx, cy, coefficients, ...)."""
        names = ("focal_px", "cx", "cy", *cls.coefficients)
        return cls(width, height, **{k: float(v) for k, v in zip(names, params, strict=False)})

    @property
    def distorted(self) -> bool:
        """Whether the model has non-zero distortion coefficients."""
        return any(getattr(self, name) for name in self.coefficients)

    @property
    def half_diagonal_rad(self) -> float:
        """Largest angle (radians) between the boresight and a corner of the image (within
        the lens's image circle)."""
        k = kernels()
        return float(k.half_diagonal(self.model_code, self.params, self.width, self.height))

    @property
    def diagonal_deg(self) -> float:
        """The field (degrees) across the diagonal: twice ``half_diagonal_rad``."""
        return math.degrees(2.0 * self.half_diagonal_rad)

    @property
    def field_cos(self) -> float:
        """Cosine of the cone (about the boresight) outside which nothing is in the image."""
        k = kernels()
        return float(k.field_cos(self.model_code, self.params, self.width, self.height))

    @property
    def model_theta_max_rad(self) -> float:
        """The largest angle from the axis (radians) the model maps before its radius stops
        growing (orthographic: 90°)."""
        return float(kernels().model_theta_max(self.model_code))

    @functools.cached_property
    def scale_px_per_rad(self) -> float:
        """Pixels per radian of sky at the lens's coarsest over the field (the smaller of the
        radial and tangential scales), at least ``MIN_SCALE_FRACTION`` of ``focal_px``: what
        the identification's tolerances divide by."""
        g_slope = kernels().radial_g
        top = self.half_diagonal_rad
        scale = math.inf
        for theta in np.linspace(0.0, top, _SCALE_SAMPLES)[1:]:
            g, slope = g_slope(self.model_code, self.params, float(theta))
            scale = min(scale, slope, g / math.sin(theta))
        return self.focal_px * max(min(scale, 1.0), MIN_SCALE_FRACTION)

    def with_focal(self, focal_px: float):
        """The same camera with another focal length."""
        return dataclasses.replace(self, focal_px=focal_px)

    def undistorted(self):
        """The same camera with its coefficients at zero: the model's own radius r(θ), which
        its ``fits_projection`` describes exactly (SIP polynomials map the distortion to it)."""
        return dataclasses.replace(self, **dict.fromkeys(self.coefficients, 0.0))

    def pixels_to_bearings(self, xy: np.ndarray) -> np.ndarray:
        """Unit bearing vectors (n, 3) in the camera frame for pixel positions (n, 2)."""
        xy = np.ascontiguousarray(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return kernels().pixels_to_bearings(self.model_code, self.params, xy)

    def bearings_to_pixels(self, c: np.ndarray) -> np.ndarray:
        """Pixel positions (n, 2) of camera-frame vectors (n, 3) the lens sees."""
        c = np.ascontiguousarray(np.asarray(c, dtype=np.float64).reshape(-1, 3))
        return kernels().bearings_to_pixels(self.model_code, self.params, c)

    def project_with_jacobian(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixels (n, 2) of camera-frame vectors (n, 3), d(pixel)/d(direction) (n, 2, 3) and
        d(pixel)/d(log focal_px, coefficients...) (n, 2, ``kernels.N_INTRINSIC``): what the
        attitude fit uses."""
        c = np.ascontiguousarray(np.asarray(c, dtype=np.float64).reshape(-1, 3))
        return kernels().project_all(self.model_code, self.params, c)

    def sees(self, c: np.ndarray) -> np.ndarray:
        """Boolean mask of unit camera-frame directions (n, 3) that land inside the image."""
        c = np.ascontiguousarray(np.asarray(c, dtype=np.float64).reshape(-1, 3))
        return kernels().sees_all(
            self.model_code, self.params, float(self.width), float(self.height), self.field_cos, c
        )

    def contains(self, xy: np.ndarray, margin_px: float = 0.0) -> np.ndarray:
        """Boolean mask of pixel positions inside the image, grown by ``margin_px``."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        return (
            (xy[:, 0] >= -margin_px)
            & (xy[:, 0] <= self.width + margin_px)
            & (xy[:, 1] >= -margin_px)
            & (xy[:, 1] <= self.height + margin_px)
        )

    def check_monotonic(self, where: str) -> None:
        """A one-line error when the image radius stops growing with the angle from the axis
        before it reaches the farthest corner or the image circle (the model would fold the
        image back)."""
        corner = math.hypot(max(self.cx, self.width - self.cx), max(self.cy, self.height - self.cy))
        top = kernels().model_theta_max(self.model_code)
        if len(self.params) > kernels().THETA_LIMIT:  # a fisheye: up to its image circle
            top = min(top, float(self.params[kernels().THETA_LIMIT]))
        g_slope = kernels().radial_g
        for theta in np.linspace(0.0, top, _MONOTONIC_SAMPLES, endpoint=False)[1:]:
            g, slope = g_slope(self.model_code, self.params, float(theta))
            if self.focal_px * g >= corner:
                return
            if not slope > 0.0:
                raise CameraError(
                    f"{where}: the {self.model} model's radius r(θ) stops increasing at "
                    f"θ = {math.degrees(theta):.1f}° (r = {self.focal_px * g:.0f} px) inside "
                    f"the image (corner at {corner:.0f} px): check its coefficients"
                )

    def file_keys(self) -> tuple[str, ...]:
        """The keys of this model's camera file, besides ``model``."""
        return ("width", "height", "focal_px", "cx", "cy", *self.coefficients)

    def to_dict(self) -> dict:
        """The camera-file form (``load_camera`` reads it back)."""
        out: dict = {"model": self.model}
        out.update({key: getattr(self, key) for key in self.file_keys()})
        out["fov_deg"] = self.fov_deg
        return out

    @classmethod
    def read_values(cls, data: dict, where: str, keys: tuple[str, ...]) -> dict:
        """The numbers under ``keys`` of a camera-file object, checked (one-line errors
        naming the key)."""
        missing = [k for k in keys if k not in data]
        if missing:
            raise CameraError(f"{where} lacks {', '.join(missing)} ({cls.model} model)")
        values = {}
        for key in keys:
            value = data[key]
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise CameraError(f"{where}: {key} must be a number, got {value!r}")
            if not np.isfinite(value):
                raise CameraError(f"{where}: {key} must be finite, got {value!r}")
            values[key] = value
        if values["width"] != int(values["width"]) or values["height"] != int(values["height"]):
            raise CameraError(f"{where}: width and height must be whole pixels")
        values["width"], values["height"] = int(values["width"]), int(values["height"])
        return values

    @classmethod
    def from_dict(cls, data: dict, where: str):
        """The camera of a camera file's object (``where`` names it in errors)."""
        keys = ("width", "height", "focal_px", "cx", "cy", *cls.coefficients)
        values = cls.read_values(data, where, keys)
        values.update(cls.optional_values(data, where))
        try:
            camera = cls(**values)
        except CameraError as exc:
            raise CameraError(f"{where}: {exc}") from None
        camera.check_monotonic(where)
        return camera

    @classmethod
    def optional_values(cls, data: dict, where: str) -> dict:
        """The model's optional camera-file keys present in ``data`` (none here)."""
        return {}
