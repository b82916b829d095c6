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
