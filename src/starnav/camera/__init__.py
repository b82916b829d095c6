"""Camera models: pixels <-> bearing vectors in the camera frame, and the camera file."""

from starnav.camera.fisheye import (
    Equidistant,
    Equisolid,
    Fisheye,
    KannalaBrandt,
    Orthographic,
    Stereographic,
)
from starnav.camera.model import (
    MODELS,
    CameraModel,
    camera_from_dict,
    load_camera,
    model_class,
    register_model,
    save_camera,
)
from starnav.camera.pinhole import Camera, focal_px_from_fov

__all__ = [
    "MODELS",
    "Camera",
    "CameraModel",
    "Equidistant",
    "Equisolid",
    "Fisheye",
    "KannalaBrandt",
    "Orthographic",
    "Stereographic",
    "camera_from_dict",
    "focal_px_from_fov",
    "load_camera",
    "model_class",
    "register_model",
    "save_camera",
]
