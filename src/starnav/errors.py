"""Errors raised for bad input. All derive from ``StarnavError`` (a ``ValueError``)."""

from __future__ import annotations


class StarnavError(ValueError):
    """Bad input to starnav; the message names the offending value."""


class StarListError(StarnavError):
    """A star list (centroids) that cannot be used: wrong columns, NaN, duplicates, ..."""


class CatalogError(StarnavError):
    """A catalog that cannot be read or holds no usable stars."""


class CameraError(StarnavError):
    """Impossible camera parameters (field of view, image size, focal length)."""


class PointingError(StarnavError):
    """Three stars that cannot give a boresight (wrong count, identical, collinear, ...)."""


class ImageError(StarnavError):
    """An image file that cannot be read or holds no usable picture."""


def shown(value: object) -> str:
    """``value`` as an error message shows it: its repr, with numpy scalars as the plain
    Python numbers they hold (``nan``, ``12.5``, ``3``, not ``np.float64(nan)``), also inside
    a tuple or list."""
    if isinstance(value, tuple | list):
        items = ", ".join(shown(v) for v in value)
        if isinstance(value, list):
            return f"[{items}]"
        return f"({items}{',' if len(value) == 1 else ''})"
    item = getattr(value, "item", None)
    if item is not None and getattr(value, "shape", None) == ():  # a numpy scalar or 0-d array
        value = item()
    return repr(value)
