"""Picture of an identified star map: measured points, catalog stars, ids and residuals."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from starnav.camera import Camera
from starnav.catalog import Catalog
from starnav.errors import StarnavError
from starnav.results import Solution
from starnav.simulate import project_catalog


def plot_solution(
    solution: Solution,
    camera: Camera,
    catalog: Catalog,
    path: str | Path,
    *,
    residual_scale: float | None = None,
) -> Path:
    """Write a PNG of the image plane (pixels, y down) with the solution drawn on it.

    Circles: measured points (blue identified, red not a catalog star); crosses: catalog stars
    projected with the solved attitude (grey where nothing was measured); arrows: residuals
    magnified ``residual_scale`` times (default: longest arrow about 5 % of the image).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cam = camera.with_focal(solution.focal_px)
    rows, proj = project_catalog(catalog, solution.R_cam_from_icrs, cam)
    xy = np.array([[m.x, m.y] for m in solution.stars])
    matched = np.array([m.catalog_id is not None for m in solution.stars])
    where = dict(zip(catalog.ids[rows].tolist(), proj, strict=True))

    fig, ax = plt.subplots(figsize=(7.5, 7.5 * cam.height / cam.width + 0.6))
    ax.add_patch(plt.Rectangle((0, 0), cam.width, cam.height, fill=False, color="0.3"))
    seen = {m.catalog_id for m in solution.stars if m.catalog_id is not None}
    unseen = np.array([p for i, p in where.items() if i not in seen]).reshape(-1, 2)
    ax.plot(*unseen.T, "x", color="0.6", ms=6, label="catalog star, not measured")
    ax.plot(*xy[matched].T, "o", mfc="none", mec="tab:blue", ms=10, label="identified")
    ax.plot(*xy[~matched].T, "o", mfc="none", mec="tab:red", ms=10, label="not a catalog star")
    if matched.any():
        rows = catalog.rows([m.catalog_id for m in solution.stars if m.catalog_id is not None])
        predicted = cam.bearings_to_pixels(catalog.vectors[rows] @ solution.R_cam_from_icrs.T)
        ax.plot(*predicted.T, "+", color="k", ms=8, label="catalog star (solved attitude)")
        d = predicted - xy[matched]
        longest = float(np.max(np.linalg.norm(d, axis=1))) or 1.0
        scale = residual_scale or 0.05 * max(cam.width, cam.height) / longest
        ax.quiver(
            *xy[matched].T,
            *(scale * d).T,
            angles="xy",
            scale_units="xy",
            scale=1,
            color="tab:orange",
            width=0.003,
            label=f"residual x{scale:.0f}",
        )
    for m in solution.stars:
        text = m.label if m.catalog_id is None else f"{m.label}: {m.catalog_id}"
        ax.annotate(text, (m.x, m.y), xytext=(6, 4), textcoords="offset points", fontsize=7)
    ax.set_xlim(-0.03 * cam.width, 1.03 * cam.width)
    ax.set_ylim(1.03 * cam.height, -0.03 * cam.height)  # y down, origin top-left
    ax.set_aspect("equal")
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    ax.set_title(
        f"RA {solution.ra_deg:.4f}°  Dec {solution.dec_deg:+.4f}°  roll {solution.roll_deg:.3f}°"
        f"  parity {solution.parity:+d}\n{solution.n_matched}/{len(solution.stars)} identified, "
        f"rms {solution.rms_px:.3f} px, false-match p {solution.false_match_probability:.1e}",
        fontsize=9,
    )
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncol=3, fontsize=7, frameon=False)
    fig.tight_layout()
    path = Path(path)
    try:
        fig.savefig(path, dpi=110)
    except OSError as exc:
        raise StarnavError(f"cannot write plot {str(path)!r}: {exc.strerror}") from None
    finally:
        plt.close(fig)
    return path
