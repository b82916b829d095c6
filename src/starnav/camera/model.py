"""The camera-model seam: what every lens model provides, the registry of models, and the
camera file.

A lens model is a frozen dataclass with the methods of ``CameraModel`` (most from
``camera.lens.Lens``) whose arithmetic is a branch of ``camera.kernels.project`` /
``unproject``, and with the class-level facts of ``Lens`` (kind, whether its focal length is
scanned, field-of-view range and limits, FITS projection, SIP order), registered in
``MODELS`` by its name in camera files (``register_model``): the pinhole (``pinhole.py``) and
the fisheye family (``fisheye.py``). The attitude fit and the verification use only this
interface (and the kernels by model code), so no other module writes a projection; the
solve, the detection, the renderer and the FITS writer ask a model's class for its facts
(``model_class(name).scans_focal``, ``camera.fits_projection``), never its name.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import ClassVar, Protocol

import numpy as np

from starnav.camera.fisheye import (
    Equidistant,
    Equisolid,
    KannalaBrandt,
    Orthographic,
    Stereographic,
)
from starnav.camera.lens import KINDS
from starnav.camera.pinhole import Camera
from starnav.errors import CameraError


class CameraModel(Protocol):
    """Pixels <-> camera-frame bearings for one lens.

    ``params``: the parameter vector the kernels take; ``model_code``: its branch there;
    ``model``: the name in camera files; the other class attributes: the model's facts
    (``camera.lens.Lens``).
    """

    width: int
    height: int
    focal_px: float
    cx: float
    cy: float
    params: np.ndarray
    model: ClassVar[str]
    model_code: ClassVar[int]
    coefficients: ClassVar[tuple[str, ...]]
    kind: ClassVar[str]
    scans_focal: ClassVar[bool]
    default_fov_range_deg: ClassVar[tuple[float, float]]
    fov_limits_deg: ClassVar[tuple[float, float]]
    fits_projection: ClassVar[str]
    sip_max_order: ClassVar[int]

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

    def undistorted(self) -> CameraModel: ...

    @classmethod
    def from_params(cls, width: int, height: int, params: np.ndarray) -> CameraModel: ...

    def to_dict(self) -> dict: ...


# the lens models by their names in camera files, in the order help texts list them
MODELS: dict[str, type] = {}


def _range_within(pair, limits: tuple[float, float] = (0.0, 360.0)) -> bool:
    return (
        isinstance(pair, tuple)
        and len(pair) == 2
        and all(isinstance(v, int | float) and not isinstance(v, bool) for v in pair)
        and limits[0] <= pair[0] < pair[1] <= limits[1]
    )


def register_model(cls: type) -> type:
    """Make the lens model class ``cls`` known by its name in camera files (``cls.model``):
    camera files, ``model_class``, the ``--lens`` choices and every solve then take it.
    Checks the facts it declares (``camera.lens.Lens``); returns ``cls`` (a class decorator
    too). Registering a class again under its name does nothing; another class under a name
    taken is an error."""
    name = getattr(cls, "model", "")
    if not (isinstance(name, str) and name):
        raise CameraError(f"lens model class {cls.__name__} has no model name")
    if MODELS.get(name, cls) is not cls:
        raise CameraError(f"the lens model name {name!r} is taken by {MODELS[name].__name__}")
    problems = []
    code = getattr(cls, "model_code", -1)
    if isinstance(code, bool) or not (isinstance(code, int) and code >= 0):
        problems.append(f"model_code {code!r} is not a branch of camera.kernels")
    if getattr(cls, "kind", None) not in KINDS:
        problems.append(f"kind {getattr(cls, 'kind', None)!r} is not one of {KINDS}")
    if not isinstance(getattr(cls, "scans_focal", None), bool):
        problems.append("scans_focal is not True or False")
    limits = getattr(cls, "fov_limits_deg", None)
    if not _range_within(limits):
        problems.append(f"fov_limits_deg {limits!r} is not a range within 0..360 degrees")
    elif not _range_within(getattr(cls, "default_fov_range_deg", None), limits):
        problems.append(f"default_fov_range_deg is not a range within {limits}")
    projection = getattr(cls, "fits_projection", "")
    if not (isinstance(projection, str) and len(projection) == 3 and projection.isupper()):
        problems.append(f"fits_projection {projection!r} is not a FITS projection code")
    order = getattr(cls, "sip_max_order", 0)
    if isinstance(order, bool) or not (isinstance(order, int) and order >= 2):
        problems.append(f"sip_max_order {order!r} is not an order of 2 or more")
    if problems:
        raise CameraError(f"lens model {name!r} ({cls.__name__}): " + "; ".join(problems))
    MODELS[name] = cls
    return cls


def model_class(name: str) -> type:
    """The lens model class registered as ``name`` (``MODELS``): ask it for the model's facts
    (``model_class(lens).scans_focal``); a one-line ``CameraError`` for an unknown name."""
    if name not in MODELS:
        raise CameraError(f"unknown lens model {name!r}; known: {', '.join(MODELS)}")
    return MODELS[name]


for _cls in (Camera, Equidistant, Equisolid, Stereographic, Orthographic, KannalaBrandt):
    register_model(_cls)


def camera_from_dict(data: dict, where: str = "camera") -> CameraModel:
    """The camera of a camera-file object; without ``"model"`` it is a pinhole."""
    if not isinstance(data, dict):
        raise CameraError(f"{where} must hold a JSON object")
    name = data.get("model", Camera.model)
    if name not in MODELS:
        raise CameraError(f"{where}: unknown camera model {name!r}; known: {', '.join(MODELS)}")
    return MODELS[name].from_dict(data, where)


def save_camera(path: str | Path, camera: CameraModel, **extra: object) -> None:
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
