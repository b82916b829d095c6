"""Annotated picture of a solved image: detections, catalog stars, ids, names and residuals.

The image is drawn in starnav's pixel convention (origin at the top-left corner, y down) with
``extent=(0, width, height, 0)``, so a point at pixel (x, y) lands on the pixel whose centre it
is. ``annotation_figure`` builds the matplotlib Figure (no pyplot, no global state) and
``annotate_image`` writes it as a PNG whose long side is 1024..1600 px (``figure_size_px``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from astropy.stats import sigma_clipped_stats
from astropy.visualization import AsinhStretch, ImageNormalize
from matplotlib import patheffects
from matplotlib.axes import Axes
from matplotlib.collections import PathCollection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.path import Path as MarkerPath

from starnav.camera import CameraModel
from starnav.catalog import Catalog
from starnav.catalog.names import star_names
from starnav.errors import ImageError, StarnavError, shown
from starnav.geometry import radec_roll_from_attitude
from starnav.simulate import project_catalog

DPI = 100
MIN_LONG_SIDE_PX = 1024  # small images are enlarged so that labels stay readable
MAX_LONG_SIDE_PX = 1600
TITLE_LINE_PX = 20
TITLE_PAD_PX = 12
# Display stretch (see _display_norm): black at sky - 1 sigma, white at the 99.99th percentile,
# asinh with its linear part about LINEAR_SIGMAS noise sigmas wide.
STRETCH_UPPER_PERCENTILE = 99.99
LINEAR_SIGMAS = 10.0
_STATISTICS_SAMPLES = 250_000
_RANKS_SHOWN = 30  # detections numbered by rank in an unsolved image's picture
OUTLINE = [patheffects.withStroke(linewidth=2.0, foreground="black")]
# a cross with an open centre, so that the star it marks stays visible
_OPEN_CROSS = MarkerPath(
    [(-1, 0), (-0.4, 0), (0.4, 0), (1, 0), (0, -1), (0, -0.4), (0, 0.4), (0, 1)],
    [MarkerPath.MOVETO, MarkerPath.LINETO] * 4,
)


def figure_size_px(width: int, height: int, *, title_lines: int = 1) -> tuple[int, int]:
    """(width, height) in pixels of the PNG for an image of ``width`` x ``height`` px:
    the image scaled so its long side is within 1024..1600 px, plus a title strip."""
    long_side = max(width, height)
    scale = min(max(long_side, MIN_LONG_SIDE_PX), MAX_LONG_SIDE_PX) / long_side
    strip = TITLE_PAD_PX + TITLE_LINE_PX * title_lines
    return round(width * scale), round(height * scale) + strip


def gray_image(image: np.ndarray, width: int, height: int) -> np.ndarray:
    """``image`` (2-D, or colour (h, w, 3|4): their mean) as a float array, checked against the
    camera's ``width`` x ``height``; ``ImageError`` (one line) otherwise."""
    data = np.asarray(image)
    if data.ndim == 3 and data.shape[2] in (3, 4):
        data = data[:, :, :3].astype(float).mean(axis=2)
    if data.ndim != 2:
        raise ImageError(
            f"image must be 2-D (height, width) or colour (height, width, 3|4), got {data.shape}"
        )
    if data.shape != (height, width):
        raise ImageError(
            f"image shape {data.shape} does not match the camera (height {height}, width {width})"
        )
    if data.dtype.kind not in "uifb":
        raise ImageError(f"image must hold numbers, got dtype {data.dtype}")
    return data.astype(float)


def _display_norm(gray: np.ndarray) -> ImageNormalize:
    """Sky-relative asinh stretch: the sky a dark grey with its noise subdued, stars at a few
    sigma clearly visible, bright stars saturating only in their cores."""
    step = max(1, int(np.sqrt(gray.size / _STATISTICS_SAMPLES)))
    sample = gray[::step, ::step]
    sample = sample[np.isfinite(sample)]
    if sample.size == 0:
        raise ImageError("image has no finite pixel values")
    _, sky, sigma = sigma_clipped_stats(sample, sigma=3.0, maxiters=5)
    if not sigma > 0:  # a flat or synthetic noiseless sky
        sigma = max(float(np.std(sample)), 1e-12) * 0.01
    vmin = sky - sigma
    vmax = max(float(np.percentile(sample, STRETCH_UPPER_PERCENTILE)), sky + 20.0 * sigma)
    a = float(np.clip(LINEAR_SIGMAS * sigma / (vmax - vmin), 1e-3, 1.0))
    return ImageNormalize(vmin=vmin, vmax=vmax, stretch=AsinhStretch(a), clip=True)


def _matched_rows(matched) -> np.ndarray:
    rows = np.asarray(matched, dtype=float) if len(matched) else np.empty((0, 5))
    if rows.ndim != 2 or rows.shape[1] != 5 or not np.isfinite(rows).all():
        raise StarnavError(
            "matched must be rows of (x, y, catalog_id, residual_dx_px, residual_dy_px) "
            f"with finite values, got shape {rows.shape}"
        )
    return rows


def _xy(points, what: str) -> np.ndarray:
    xy = np.asarray(points, dtype=float)
    if xy.size == 0:
        return np.empty((0, 2))
    if xy.ndim != 2 or xy.shape[1] != 2 or not np.isfinite(xy).all():
        raise StarnavError(f"{what} must be an (n, 2) array of finite pixels, got {xy.shape}")
    return xy


def _title_lines(R: np.ndarray, camera: CameraModel, title: str | None, counts: str) -> list[str]:
    ra, dec, roll, parity = radec_roll_from_attitude(R)
    line = (
        f"RA {ra:.4f}°  Dec {dec:+.4f}°  roll {roll:.3f}°  FOV {camera.fov_deg:.3f}° "
        f"({camera.model})  parity {parity:+d}  ({counts})"
    )
    return [*([] if title is None else title.splitlines()), line]


def annotation_figure(
    image: np.ndarray,
    *,
    detected_xy: np.ndarray,
    R_cam_from_icrs: np.ndarray,
    camera: CameraModel,
    catalog: Catalog,
    matched: Sequence[Sequence[float]] | np.ndarray,
    residual_scale: float = 50.0,
    title: str | None = None,
    names: Mapping[int, str] | None = None,
) -> Figure:
    """The annotated image as a matplotlib Figure (see ``annotate_image`` for the arguments)."""
    if not (np.isfinite(residual_scale) and residual_scale > 0):
        raise StarnavError(f"residual_scale must be a positive number, got {shown(residual_scale)}")
    gray = gray_image(image, camera.width, camera.height)
    detected = _xy(detected_xy, "detected_xy")
    match = _matched_rows(matched)
    R = np.asarray(R_cam_from_icrs, dtype=float)
    if R.shape != (3, 3) or not np.isfinite(R).all():
        raise StarnavError(f"R_cam_from_icrs must be a finite 3x3 matrix, got shape {R.shape}")
    if names is None:
        # the names are keyed by HIP number: other catalogs' ids mean other stars
        names = star_names() if catalog.name.startswith("Hipparcos") else {}

    lines = _title_lines(R, camera, title, f"{len(detected)} detected, {len(match)} matched")
    fig_w, fig_h = figure_size_px(camera.width, camera.height, title_lines=len(lines))
    fig, ax = image_figure(gray, fig_w, fig_h, len(lines))
    rows, xy = project_catalog(catalog, R, camera)
    ids = catalog.ids[rows]
    handles = _catalog_markers(ax, xy, ids, match, catalog, R, camera)
    if len(detected):
        handles.append(_circles(ax, detected, "detected"))
    if len(match):
        handles.append(_residuals_and_ids(ax, match, residual_scale))
    _name_labels(ax, ids, xy, names)
    if handles:
        dark_legend(ax, handles)
    figure_title(fig, lines, fig_h)
    return fig


def _circles(
    ax: Axes, xy: np.ndarray, label: str, *, size=40, color="cyan", width=0.9
) -> PathCollection:
    """Open circles at detections ``xy`` (n, 2, px): the marker of detected stars."""
    return ax.scatter(*xy.T, marker="o", s=size, facecolors="none", edgecolors=color,
                      linewidths=width, label=label)  # fmt: skip


def figure_title(fig: Figure, lines: list[str], fig_h: int) -> None:
    """The title ``lines`` in the strip above the image of a ``fig_h`` px figure."""
    fig.text(
        0.5,
        1.0 - (TITLE_PAD_PX / 2) / fig_h,
        "\n".join(lines),
        ha="center",
        va="top",
        fontsize=10,
        linespacing=1.3,
    )


def unsolved_figure(
    image: np.ndarray, *, detected_xy: np.ndarray, used: int, lines: Sequence[str]
) -> Figure:
    """An image that was not solved, to see why: the detections handed to the solver
    (``detected_xy``, brightest first), the first ``used`` (those the star patterns are made
    of) as cyan circles numbered by rank, the others as dim circles, and the title ``lines``
    (the reason, what was tried)."""
    height, width = np.asarray(image).shape[:2]
    gray = gray_image(image, width, height)
    detected = _xy(detected_xy, "detected_xy")
    lines = list(lines)
    fig_w, fig_h = figure_size_px(width, height, title_lines=len(lines))
    fig, ax = image_figure(gray, fig_w, fig_h, len(lines))
    handles = []
    given, rest = detected[:used], detected[used:]
    if len(rest):
        dim = {"size": 30, "color": "#557788", "width": 0.7}
        handles.append(_circles(ax, rest, "detected (verification only)", **dim))
    if len(given):
        handles.append(_circles(ax, given, f"brightest {len(given)} (patterns)"))
        for rank, (x, y) in enumerate(given[:_RANKS_SHOWN], start=1):
            ax.annotate(str(rank), (x, y), xytext=(5, 5), textcoords="offset points",
                        color="cyan", fontsize=7, path_effects=OUTLINE)  # fmt: skip
    if handles:
        dark_legend(ax, handles)
    figure_title(fig, lines, fig_h)
    return fig


def save_figure(fig: Figure, path_out: str | Path) -> None:
    """Write ``fig`` as a PNG, or a one-line error."""
    try:
        fig.savefig(path_out, format="png", dpi=DPI)
    except OSError as exc:
        raise StarnavError(f"cannot write image {str(path_out)!r}: {exc}") from None


def image_figure(gray: np.ndarray, fig_w: int, fig_h: int, title_lines: int) -> tuple[Figure, Axes]:
    """A ``fig_w`` x ``fig_h`` px figure with the stretched image drawn in starnav's pixel
    convention below a strip for ``title_lines`` lines of title; the figure and the image
    axes."""
    height, width = gray.shape
    # 0.01 px of slack: matplotlib truncates figsize * dpi to whole pixels
    fig = Figure(figsize=((fig_w + 0.01) / DPI, (fig_h + 0.01) / DPI), dpi=DPI, facecolor="white")
    image_h = fig_h - (TITLE_PAD_PX + TITLE_LINE_PX * title_lines)
    # matplotlib resamples what it is given in several full-size copies: a 200 MP image took
    # gigabytes; binned to about the figure's pixels first, it draws the same picture
    gray = _binned(gray, max(1, min(width // max(fig_w, 1), height // max(image_h, 1))))
    ax = fig.add_axes((0.0, 0.0, 1.0, image_h / fig_h))
    ax.set_axis_off()
    ax.imshow(
        gray, cmap="gray", norm=_display_norm(gray), extent=(0, width, height, 0), origin="upper"
    )
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)
    return fig, ax


def _binned(gray: np.ndarray, factor: int) -> np.ndarray:
    """``gray`` averaged in ``factor`` x ``factor`` blocks (the last partial ones dropped), a
    row of blocks at a time (no full-size temporary); itself for ``factor`` 1."""
    if factor <= 1:
        return gray
    rows, cols = gray.shape[0] // factor, gray.shape[1] // factor
    out = np.empty((rows, cols))
    for r in range(rows):
        block = gray[r * factor : (r + 1) * factor, : cols * factor]
        out[r] = block.reshape(factor, cols, factor).mean(axis=(0, 2))
    return out


def _catalog_markers(
    ax: Axes,
    xy: np.ndarray,
    ids: np.ndarray,
    match: np.ndarray,
    catalog: Catalog,
    R: np.ndarray,
    camera: CameraModel,
) -> list:
    """Draw the catalog stars in view (``ids`` at ``xy``): orange crosses for those not in
    ``match``, green squares where the matched ones project; their legend handles."""
    is_matched = np.isin(ids, list({int(i) for i in match[:, 2]}))
    handles = []
    if (~is_matched).any():
        handles.append(
            ax.scatter(
                *xy[~is_matched].T,
                marker=_OPEN_CROSS,
                s=90,
                c="orange",
                linewidths=1.0,
                label="catalog star (solution), not matched",
            )
        )
    if len(match):
        cat_rows = catalog.rows(match[:, 2].astype(np.int64))
        c = catalog.vectors[cat_rows] @ R.T
        front = c[:, 2] > 0
        predicted = camera.bearings_to_pixels(c[front])
        handles.append(
            ax.scatter(
                *predicted.T,
                marker="s",
                s=110,
                facecolors="none",
                edgecolors="lime",
                linewidths=1.0,
                label="catalog star, matched",
            )
        )
    return handles


def _residuals_and_ids(ax: Axes, match: np.ndarray, residual_scale: float) -> Line2D:
    """Draw the residual arrows of the matched points, magnified ``residual_scale`` times,
    and their catalog ids; the legend handle of the arrows."""
    ax.quiver(
        match[:, 0],
        match[:, 1],
        residual_scale * match[:, 3],
        residual_scale * match[:, 4],
        angles="xy",
        scale_units="xy",
        scale=1.0,
        color="red",
        width=0.002,
        zorder=4,
    )
    handle = Line2D(
        [],
        [],
        color="red",
        marker=r"$\rightarrow$",
        markersize=12,
        linestyle="none",
        label=f"residual (catalog - measured) x{residual_scale:g}",
    )
    for x, y, cid in match[:, :3]:
        ax.annotate(
            str(int(cid)),
            (x, y),
            xytext=(7, -9),
            textcoords="offset points",
            color="lime",
            fontsize=7,
            path_effects=OUTLINE,
            zorder=5,
        )
    return handle


def _name_labels(ax: Axes, ids: np.ndarray, xy: np.ndarray, names: Mapping[int, str]) -> None:
    """Label the catalog stars in view that have a name."""
    for star_id, (x, y) in zip(ids.tolist(), xy, strict=True):
        name = names.get(int(star_id))
        if name is not None:
            ax.annotate(
                name,
                (x, y),
                xytext=(8, 6),
                textcoords="offset points",
                color="yellow",
                fontsize=10,
                fontweight="bold",
                path_effects=OUTLINE,
                zorder=6,
            )


def dark_legend(ax: Axes, handles: list) -> None:
    """The legend of ``handles``, white on translucent black, at the lower left."""
    legend = ax.legend(handles=handles, loc="lower left", fontsize=8, framealpha=0.6)
    legend.get_frame().set_facecolor("black")
    for text in legend.get_texts():
        text.set_color("white")


def annotate_image(
    path_out: str | Path,
    image: np.ndarray,
    *,
    detected_xy: np.ndarray,
    R_cam_from_icrs: np.ndarray,
    camera: CameraModel,
    catalog: Catalog,
    matched: Sequence[Sequence[float]] | np.ndarray,
    residual_scale: float = 50.0,
    title: str | None = None,
    names: Mapping[int, str] | None = None,
) -> None:
    """Write a PNG of ``image`` (2-D, or colour (h, w, 3|4), shape matching ``camera``) with:

    - ``detected_xy`` (n, 2, starnav pixels) as cyan circles;
    - the catalog stars in the image at the solution (``R_cam_from_icrs``, ``camera``) as
      orange crosses, those in ``matched`` as green squares labelled with their catalog id;
    - ``matched``: rows (x, y, catalog_id, residual_dx_px, residual_dy_px) of measured points,
      residual = catalog position minus measured (px), drawn from (x, y) magnified
      ``residual_scale`` times (the legend says so);
    - the IAU name of every named star in view (``names``: {catalog id: name}; default the
      bright-star names for a Hipparcos catalog, none for other catalogs);
    - a title: ``title`` (optional lines) and RA/Dec/roll/FOV/parity of the solution.
    """
    fig = annotation_figure(
        image,
        detected_xy=detected_xy,
        R_cam_from_icrs=R_cam_from_icrs,
        camera=camera,
        catalog=catalog,
        matched=matched,
        residual_scale=residual_scale,
        title=title,
        names=names,
    )
    save_figure(fig, path_out)
