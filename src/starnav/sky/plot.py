"""The picture of the sky's state: the frame (stretched as ``starnav.output.annotate`` draws
it), the cloud map over it (red cloudy, yellow partly, green clear; uncoloured where there is
no data), the expected stars seen (green circles) and missed (red crosses), the fainter stars
seen (small green dots), and the cells' grid (altitude rings and azimuth sectors, or the
camera-frame rings about the boresight) with each cell's state letter."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.colors import ListedColormap
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

from starnav.camera import CameraModel
from starnav.geometry import radec_to_unit
from starnav.output.annotate import (
    OUTLINE,
    dark_legend,
    figure_size_px,
    figure_title,
    gray_image,
    image_figure,
    save_figure,
)
from starnav.sky.state import CLEAR_FRACTION, CLOUDY_FRACTION, SkyState

_STATE_COLOURS = ("#d62728", "#f2c40f", "#2ca02c")  # cloudy, partly, clear
_LETTER = {"clear": "C", "partly": "P", "cloudy": "X", "no data": "·"}
_MAP_ALPHA = 0.3


def _local_to_pixels(v_local: np.ndarray, state: SkyState, R: np.ndarray, camera: CameraModel):
    """Pixels of (n, 3) vectors in the cells' frame; NaN where the camera does not see them."""
    c = v_local @ state.R_frame_from_icrs @ R.T
    out = np.full((len(c), 2), np.nan)
    ok = camera.sees(c)
    if ok.any():
        out[ok] = camera.bearings_to_pixels(c[ok])
    return out


def _altaz_vectors(alt_deg: np.ndarray, az_deg: np.ndarray) -> np.ndarray:
    """(East, North, Up)-like unit vectors of altitudes and azimuths (degrees)."""
    return radec_to_unit(np.radians(90.0 - np.asarray(az_deg)), np.radians(np.asarray(alt_deg)))


def _grid(ax, state: SkyState, R: np.ndarray, camera: CameraModel) -> None:
    """The cells' boundaries and state letters."""
    rings = sorted({c.alt_min_deg for c in state.cells} | {c.alt_max_deg for c in state.cells})
    az = np.linspace(0.0, 360.0, 361)
    for alt in rings[:-1]:
        xy = _local_to_pixels(_altaz_vectors(np.full_like(az, alt), az), state, R, camera)
        ax.plot(*xy.T, color="white", lw=0.6, alpha=0.6)
    sectors = sorted({c.az_min_deg for c in state.cells if c.az_max_deg - c.az_min_deg < 360})
    top = rings[-2] if len(rings) > 1 else 90.0
    for a in sectors:
        alts = np.linspace(rings[0], top, 60)
        xy = _local_to_pixels(_altaz_vectors(alts, np.full_like(alts, a)), state, R, camera)
        ax.plot(*xy.T, color="white", lw=0.6, alpha=0.6)
    for cell in state.cells:
        full = cell.az_max_deg - cell.az_min_deg >= 360
        alt = 90.0 if full else 0.5 * (cell.alt_min_deg + cell.alt_max_deg)
        az_mid = 0.5 * (cell.az_min_deg + cell.az_max_deg)
        xy = _local_to_pixels(_altaz_vectors(np.array([alt]), np.array([az_mid])), state, R, camera)
        if np.isfinite(xy).all():
            ax.text(*xy[0], _LETTER[cell.state], color="white", fontsize=11, ha="center",
                    va="center", fontweight="bold", path_effects=OUTLINE)  # fmt: skip
    if state.altaz:
        for name, a in (("N", 0.0), ("E", 90.0), ("S", 180.0), ("W", 270.0)):
            at = max(rings[0] - 4.0, 1.0)
            xy = _local_to_pixels(_altaz_vectors(np.array([at]), np.array([a])), state, R, camera)
            if np.isfinite(xy).all():
                ax.text(*xy[0], name, color="cyan", fontsize=12, ha="center", va="center",
                        fontweight="bold", path_effects=OUTLINE)  # fmt: skip


def sky_figure(image: np.ndarray, state: SkyState, *, R_cam_from_icrs, camera: CameraModel,
               title: str | None = None):  # fmt: skip
    """The picture of ``state`` over ``image`` (2-D, the solved frame) as a matplotlib Figure."""
    gray = gray_image(image, camera.width, camera.height)
    R = np.asarray(R_cam_from_icrs, dtype=float)
    counts = state.cell_counts()
    lines = [] if title is None else title.splitlines()
    frac = "—" if state.clear_fraction is None else f"{state.clear_fraction:.2f}"
    lim = "—" if state.limiting_mag is None else f"{state.limiting_mag:.1f}"
    lines.append(
        f"sky {state.state}: clear fraction {frac}, limiting mag {lim}; "
        f"{int((state.expected & state.seen).sum())} of {int(state.expected.sum())} expected "
        f"stars seen; cells clear {counts['clear']} / partly {counts['partly']} / cloudy "
        f"{counts['cloudy']} / no data {counts['no data']} "
        f"({'alt-az' if state.altaz else 'about the boresight'})"
    )
    fig_w, fig_h = figure_size_px(camera.width, camera.height, title_lines=len(lines))
    fig, ax = image_figure(gray, fig_w, fig_h, len(lines))
    step = state.map_step_px
    rows, cols = state.map_fraction.shape
    ax.imshow(
        np.ma.masked_invalid(state.map_fraction),
        cmap=ListedColormap(_STATE_COLOURS),
        norm=_boundaries(),
        alpha=_MAP_ALPHA,
        extent=(0, cols * step, rows * step, 0),
        origin="upper",
        interpolation="bilinear",
    )
    ax.set_xlim(0, camera.width)
    ax.set_ylim(camera.height, 0)
    exp, seen = state.expected, state.seen
    ax.scatter(*state.xy[~exp & seen].T, s=4, c="#66dd66", linewidths=0)
    ax.scatter(*state.xy[exp & seen].T, s=40, facecolors="none", edgecolors="lime", linewidths=0.9)
    ax.scatter(*state.xy[exp & ~seen].T, s=30, marker="x", c="red", linewidths=1.0)
    _grid(ax, state, R, camera)
    handles = [
        Line2D([], [], marker="o", ls="none", mfc="none", mec="lime", label="expected, seen"),
        Line2D([], [], marker="x", ls="none", c="red", label="expected, missed"),
        Line2D([], [], marker=".", ls="none", c="#66dd66", label="fainter, seen"),
        Patch(color=_STATE_COLOURS[2], alpha=0.5, label=f"clear (>= {CLEAR_FRACTION:g} seen)"),
        Patch(color=_STATE_COLOURS[1], alpha=0.5, label="partly"),
        Patch(color=_STATE_COLOURS[0], alpha=0.5, label=f"cloudy (< {CLOUDY_FRACTION:g} seen)"),
    ]
    dark_legend(ax, handles)
    figure_title(fig, lines, fig_h)
    return fig


def _boundaries():
    from matplotlib.colors import BoundaryNorm

    return BoundaryNorm([0.0, CLOUDY_FRACTION, CLEAR_FRACTION, 1.0], 3)


def plot_sky_state(
    path_out: str | Path,
    image: np.ndarray,
    state: SkyState,
    *,
    R_cam_from_icrs: np.ndarray,
    camera: CameraModel,
    title: str | None = None,
) -> None:
    """Write the picture of ``state`` (``sky_figure``) as a PNG."""
    save_figure(
        sky_figure(image, state, R_cam_from_icrs=R_cam_from_icrs, camera=camera, title=title),
        path_out,
    )
