"""The camera-model seam: what every lens model provides, and the camera file.

A lens model is a frozen dataclass with the methods of ``CameraModel`` (most from
``camera.lens.Lens``) whose arithmetic is a branch of ``camera.kernels.project`` /
``unproject``, registered in ``MODELS`` by its name in camera files: the pinhole
(``pinhole.py``) and the fisheye family (``fisheye.py``). The attitude fit and the
verification use only this interface (and the kernels by model code), so no other module
writes a projection.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Protocol

import numpy as np

from starnav.camera.fisheye import (
    Equidistant,
    Equisolid,
    KannalaBrandt,
    Orthographic,
    Stereographic,
)
from starnav.camera.pinhole import Camera
from starnav.errors import CameraError


class CameraModel(Protocol):
    """Pixels <-> camera-frame bearings for one lens.

    ``params``: the parameter vector the kernels take; ``model_code``: its branch there;
    ``model``: the name in camera files.
    """

    width: int
    height: int
    focal_px: float
    cx: float
    cy: float
    model: str
    model_code: int
    params: np.ndarray

    def pixels_to_bearings(self, xy: np.ndarray) -> np.ndarray: ...

    def bearings_to_pixels(self, c: np.ndarray) -> np.ndarray: ...

    def project_with_jacobian(self, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...

    def sees(self, c: np.ndarray) -> np.ndarray: ...

    @property
    def half_diagonal_rad(self) -> float: ...

    @property
    def diagonal_deg(self) -> float: ...

    @property
    def fov_deg(self) -> float: ...

    @property
    def distorted(self) -> bool: ...

    @property
    def scale_px_per_rad(self) -> float: ...

    def with_focal(self, focal_px: float) -> CameraModel: ...

    @classmethod
    def from_params(cls, width: int, height: int, params: np.ndarray) -> CameraModel: ...

    def to_dict(self) -> dict: ...


MODELS: dict[str, type] = {
    cls.model: cls
    for cls in (Camera, Equidistant, Equisolid, Stereographic, Orthographic, KannalaBrandt)
}


def camera_from_dict(data: dict, where: str = "camera") -> CameraModel:
    """The camera of a camera-file object; without ``"model"`` it is a pinhole."""
    if not isinstance(data, dict):
        raise CameraError(f"{where} must hold a JSON object")
    name = data.get("model", "pinhole")
    if name not in MODELS:
        raise CameraError(f"{where}: unknown camera model {name!r}; known: {', '.join(MODELS)}")
    return MODELS[name].from_dict(data, where)


def save_camera(path: str | Path, camera: CameraModel, **extra: float | int | str) -> None:
    """Write ``camera`` as a camera file (JSON; ``extra`` keys are kept as notes)."""
    data = camera.to_dict()
    data.update(extra)
    Path(path).write_text(json.dumps(data, indent=2) + "\n")


def load_camera(path: str | Path) -> CameraModel:
    """A camera from a camera file (JSON: ``model`` and its parameters, see ``MODELS``)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise CameraError(f"camera file {path} does not exist") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CameraError(f"camera file {path} is not readable JSON ({exc})") from None
    return camera_from_dict(data, f"camera file {path}")
