"""Pinhole camera: pixels <-> bearing vectors in the camera frame.

Pixels: x right, y down, origin at the top-left corner of the image (the top-left pixel's
centre is (0.5, 0.5)). Camera frame: x right, y down, z along the boresight.

Parity is not a camera property here: a mirrored image is described by an attitude matrix with
determinant -1 (see ``starnav.geometry``), so the projection below is the same for both.
Radial distortion (k1, k2 on the normalised radius) is part of the model; solving images can
fit it (``--fit-distortion``) and a camera file (JSON, ``save_camera`` / ``load_camera``,
written by ``starnav calibrate``) keeps a calibrated camera.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from starnav.errors import CameraError

CAMERA_FILE_KEYS = ("width", "height", "focal_px", "cx", "cy", "k1", "k2")


def focal_px_from_fov(fov_deg: float, width: int) -> float:
    """Focal length in pixels for a horizontal field of view (degrees) across ``width`` px."""
    return 0.5 * width / np.tan(0.5 * np.radians(fov_deg))


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

    @property
    def fov_deg(self) -> float:
        """Horizontal field of view in degrees."""
        return float(np.degrees(2.0 * np.arctan(0.5 * self.width / self.focal_px)))

    @property
    def half_diagonal_rad(self) -> float:
        """Largest angle (radians) between the boresight and a corner of the image."""
        dx = max(self.cx, self.width - self.cx)
        dy = max(self.cy, self.height - self.cy)
        return float(np.arctan(np.hypot(dx, dy) / self.focal_px))

    def with_focal(self, focal_px: float) -> Camera:
        """The same camera with another focal length."""
        return Camera(self.width, self.height, focal_px, self.cx, self.cy, self.k1, self.k2)

    def _distort_factor(self, r2: np.ndarray) -> np.ndarray:
        return 1.0 + self.k1 * r2 + self.k2 * r2 * r2

    def pixels_to_bearings(self, xy: np.ndarray) -> np.ndarray:
        """Unit bearing vectors (n, 3) in the camera frame for pixel positions (n, 2)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        u = (xy[:, 0] - self.cx) / self.focal_px
        v = (xy[:, 1] - self.cy) / self.focal_px
        if self.k1 or self.k2:
            # invert the radial model by fixed-point iteration (converges for mild distortion)
            ud, vd = u.copy(), v.copy()
            for _ in range(20):
                factor = self._distort_factor(u * u + v * v)
                u, v = ud / factor, vd / factor
        b = np.column_stack([u, v, np.ones_like(u)])
        return b / np.linalg.norm(b, axis=1, keepdims=True)

    def bearings_to_pixels(self, c: np.ndarray) -> np.ndarray:
        """Pixel positions (n, 2) of camera-frame vectors (n, 3) with positive z."""
        c = np.asarray(c, dtype=float).reshape(-1, 3)
        u = c[:, 0] / c[:, 2]
        v = c[:, 1] / c[:, 2]
        if self.k1 or self.k2:
            factor = self._distort_factor(u * u + v * v)
            u, v = u * factor, v * factor
        return np.column_stack([self.cx + self.focal_px * u, self.cy + self.focal_px * v])

    def contains(self, xy: np.ndarray, margin_px: float = 0.0) -> np.ndarray:
        """Boolean mask of pixel positions inside the image, grown by ``margin_px``."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        return (
            (xy[:, 0] >= -margin_px)
            & (xy[:, 0] <= self.width + margin_px)
            & (xy[:, 1] >= -margin_px)
            & (xy[:, 1] <= self.height + margin_px)
        )


def save_camera(path: str | Path, camera: Camera, **extra: float | int | str) -> None:
    """Write ``camera`` as a camera file (JSON; ``extra`` keys are kept as notes)."""
    data = {key: getattr(camera, key) for key in CAMERA_FILE_KEYS}
    data["fov_deg"] = camera.fov_deg
    data.update(extra)
    Path(path).write_text(json.dumps(data, indent=2) + "\n")


def load_camera(path: str | Path) -> Camera:
    """A camera from a camera file (JSON with width, height, focal_px, cx, cy, k1, k2)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise CameraError(f"camera file {path} does not exist") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CameraError(f"camera file {path} is not readable JSON ({exc})") from None
    if not isinstance(data, dict):
        raise CameraError(f"camera file {path} must hold a JSON object")
    missing = [k for k in CAMERA_FILE_KEYS if k not in data]
    if missing:
        raise CameraError(f"camera file {path} lacks {', '.join(missing)}")
    values = {}
    for key in CAMERA_FILE_KEYS:
        value = data[key]
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise CameraError(f"camera file {path}: {key} must be a number, got {value!r}")
        values[key] = value
    if values["width"] != int(values["width"]) or values["height"] != int(values["height"]):
        raise CameraError(f"camera file {path}: width and height must be whole pixels")
    values["width"], values["height"] = int(values["width"]), int(values["height"])
    return Camera(**values)
