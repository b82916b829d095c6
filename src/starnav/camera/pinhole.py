"""Pinhole camera with radial distortion: the first ``CameraModel``.

Pixels: x right, y down, origin at the top-left corner of the image (the top-left pixel's
centre is (0.5, 0.5)). Camera frame: x right, y down, z along the boresight.

Parity is not a camera property here: a mirrored image is described by an attitude matrix with
determinant -1 (see ``starnav.geometry``), so the projection is the same for both. Radial
distortion: (u, v) -> (u, v) (1 + k1 r^2 + k2 r^4) on the normalised radius r. The arithmetic
is in ``camera.kernels`` (shared with the attitude fit and the verification).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from starnav.errors import CameraError

PINHOLE_KEYS = ("width", "height", "focal_px", "cx", "cy", "k1", "k2")


def focal_px_from_fov(fov_deg: float, width: int) -> float:
    """Focal length in pixels for a horizontal field of view (degrees) across ``width`` px."""
    return 0.5 * width / np.tan(0.5 * np.radians(fov_deg))


def kernels():
    from starnav.camera import kernels  # numba: loaded when a projection is first needed

    return kernels


@dataclass(frozen=True)
class Camera:
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

    def __post_init__(self) -> None:
        for name in ("width", "height"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise CameraError(f"{name} must be a positive number of pixels, got {value!r}")
        if not (np.isfinite(self.focal_px) and self.focal_px > 0):
            raise CameraError(f"focal_px must be positive, got {self.focal_px!r}")
        if self.cx is None:
            object.__setattr__(self, "cx", self.width / 2.0)
        if self.cy is None:
            object.__setattr__(self, "cy", self.height / 2.0)
        object.__setattr__(
            self,
            "params",
            np.array([self.focal_px, self.cx, self.cy, self.k1, self.k2], dtype=np.float64),
        )

    @classmethod
    def from_fov(cls, fov_deg: float, width: int, height: int | None = None) -> Camera:
        """Camera whose horizontal field of view across ``width`` px is ``fov_deg`` degrees."""
        if not (np.isfinite(fov_deg) and 0.0 < fov_deg < 179.0):
            raise CameraError(f"fov_deg must be above 0 and below 179 degrees, got {fov_deg!r}")
        if not (np.isfinite(width) and width >= 8):
            raise CameraError(f"width must be at least 8 px, got {width!r}")
        height = width if height is None else height
        if not (np.isfinite(height) and height >= 8):
            raise CameraError(f"height must be at least 8 px, got {height!r}")
        return cls(int(width), int(height), focal_px_from_fov(fov_deg, width))

    @classmethod
    def from_params(cls, width: int, height: int, params: np.ndarray) -> Camera:
        """The camera of a parameter vector ``[focal_px, cx, cy, k1, k2]``."""
        f, cx, cy, k1, k2 = (float(v) for v in params)
        return cls(width, height, f, cx, cy, k1, k2)

    @property
    def distorted(self) -> bool:
        """Whether the model has non-zero distortion coefficients."""
        return bool(self.k1 or self.k2)

    @property
    def fov_deg(self) -> float:
        """Horizontal field of view in degrees."""
        return float(np.degrees(2.0 * np.arctan(0.5 * self.width / self.focal_px)))

    @property
    def half_diagonal_rad(self) -> float:
        """Largest angle (radians) between the boresight and a corner of the image."""
        return float(
            kernels().half_diagonal(
                self.model_code, self.params, float(self.width), float(self.height)
            )
        )

    @property
    def field_cos(self) -> float:
        """Cosine of the cone (about the boresight) outside which nothing is in the image."""
        return float(
            kernels().field_cos(self.model_code, self.params, float(self.width), float(self.height))
        )

    def with_focal(self, focal_px: float) -> Camera:
        """The same camera with another focal length."""
        return Camera(self.width, self.height, focal_px, self.cx, self.cy, self.k1, self.k2)

    def pixels_to_bearings(self, xy: np.ndarray) -> np.ndarray:
        """Unit bearing vectors (n, 3) in the camera frame for pixel positions (n, 2)."""
        xy = np.ascontiguousarray(np.asarray(xy, dtype=np.float64).reshape(-1, 2))
        return kernels().pixels_to_bearings(self.model_code, self.params, xy)

    def bearings_to_pixels(self, c: np.ndarray) -> np.ndarray:
        """Pixel positions (n, 2) of camera-frame vectors (n, 3) with positive z."""
        c = np.ascontiguousarray(np.asarray(c, dtype=np.float64).reshape(-1, 3))
        return kernels().bearings_to_pixels(self.model_code, self.params, c)

    def project_with_jacobian(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixels (n, 2) of camera-frame vectors (n, 3), d(pixel)/d(direction) (n, 2, 3) and
        d(pixel)/d(log focal_px, k1, k2) (n, 2, 3): what the attitude fit uses."""
        c = np.ascontiguousarray(np.asarray(c, dtype=np.float64).reshape(-1, 3))
        return kernels().project_all(self.model_code, self.params, c)

    def sees(self, c: np.ndarray) -> np.ndarray:
        """Boolean mask of camera-frame directions (n, 3) that land inside the image."""
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

    def to_dict(self) -> dict:
        """The camera-file form (``load_camera`` reads it back)."""
        out: dict = {"model": self.model}
        out.update({key: getattr(self, key) for key in PINHOLE_KEYS})
        out["fov_deg"] = self.fov_deg
        return out

    @classmethod
    def from_dict(cls, data: dict, where: str) -> Camera:
        """The camera of a camera file's object (``where`` names it in errors)."""
        missing = [k for k in PINHOLE_KEYS if k not in data]
        if missing:
            raise CameraError(f"{where} lacks {', '.join(missing)}")
        values = {}
        for key in PINHOLE_KEYS:
            value = data[key]
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise CameraError(f"{where}: {key} must be a number, got {value!r}")
            if not np.isfinite(value):
                raise CameraError(f"{where}: {key} must be finite, got {value!r}")
            values[key] = value
        if values["width"] != int(values["width"]) or values["height"] != int(values["height"]):
            raise CameraError(f"{where}: width and height must be whole pixels")
        values["width"], values["height"] = int(values["width"]), int(values["height"])
        return cls(**values)
