"""Camera and mount of the tudo all-sky cameras (MAGIC, IceAct) from one clear frame each, for
the sky-state tests and benchmarks/images/sky_state.py (tests/data/allsky/tudo_cameras.json).

Today's ``starnav solve`` does not solve these frames (the principal point is held at the image
centre and the lenses are not the ideal models; issue 37 point 1), so the attitude is started
independently: astrometry.net's ``solve-field`` (tycho2 index files) on a crop about the image
circle's centre (a ~40° field), its matched stars (.corr) taking a Kannala-Brandt camera
(focal length, principal point, k1, k2) and the attitude by least squares, then re-matched
over the whole frame against starnav's detections and the Hipparcos stars to magnitude 6 in
rounds of shrinking and growing radius. The mount is R_cam_from_icrs seen from the site at the
frame's time (``starnav.sky.state.mount_of``).

The camera's clear-sky limit (``mag_limit``) is the one ``starnav.sky.sky_state`` reads from
that clear frame's best cells: ``starnav sky --mount`` expects the stars to it.

Run (DIR holds the frames; writes tests/data/allsky/tudo_cameras.json to stdout):
    STARNAV_TUDO_FRAMES=DIR python benchmarks/images/sky_cameras.py
(DIR holds the frames named as in ``benchmarks.images.sky_state.TUDO``: MAGIC
20180817_0055.fits, IceAct starry.fits of tudo-astroparticlephysics/all_sky_cloud_detection
at e18e137d, tests/resources/{magic,iceact}_images/).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from astropy.io import fits
from scipy.optimize import least_squares
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from starnav.camera import model_class
from starnav.catalog import load_catalog
from starnav.detect.circle import find_image_circle
from starnav.detect.read import read_image
from starnav.detect.stars import detect_stars
from starnav.geometry import radec_to_unit
from starnav.navigation.frames import parse_utc
from starnav.sky.state import Site, mount_of, sky_state

# camera name: (frame, site (lat, lon, height, mid-exposure UTC), crop half-size px, focal px
# of the nominal lens (cameras.py: focal length / pixel pitch), field of the crop (deg))
CAMERAS = {
    "magic": (
        "magic_20180817_0055.fits",
        (28.76187, -17.890777, 2200.0, "2018-08-17T00:52:51"),
        130,
        325.0,
        (25, 70),
    ),
    "iceact": (
        "iceact_starry.fits",
        (-89.99, -63.45, 2801.0, "2017-05-03T03:13:04"),
        80,
        193.0,
        (30, 80),
    ),
}
ROUNDS_PX = (6, 4, 3, 2.5, 4, 6, 8, 4, 3, 2.5)


def crop_pairs(pixels: np.ndarray, cx: float, cy: float, half: int, field: tuple) -> tuple:
    """astrometry.net on the crop about (cx, cy): its matched (pixel (n, 2) in our
    convention, ICRS unit vector (n, 3)) pairs."""
    x0, y0 = round(cx - half), round(cy - half)
    with tempfile.TemporaryDirectory() as tmp:
        crop = Path(tmp) / "crop.fits"
        fits.writeto(crop, pixels[y0 : y0 + 2 * half, x0 : x0 + 2 * half].astype(np.float32))
        subprocess.run(
            ["solve-field", "--overwrite", "--no-plots", "--scale-units", "degwidth",
             "--scale-low", str(field[0]), "--scale-high", str(field[1]), "--cpulimit", "120",
             "-D", tmp, str(crop)],
            check=True, capture_output=True,
        )  # fmt: skip
        t = fits.open(Path(tmp) / "crop.corr")[1].data
        xy = np.column_stack([t["field_x"] - 0.5 + x0, t["field_y"] - 0.5 + y0])
        return xy, radec_to_unit(np.radians(t["index_ra"]), np.radians(t["index_dec"]))


def fit_camera(path: Path, site: tuple, half: int, focal_px: float, field: tuple) -> dict:
    pixels = read_image(path)
    height, width = pixels.shape
    circle = find_image_circle(pixels)
    kb = model_class("kannala-brandt")

    def camera(p):
        f, cx, cy, k1, k2 = (float(x) for x in (np.exp(p[3]), *p[4:]))
        return kb(width=width, height=height, focal_px=f, cx=cx, cy=cy, image_circle_deg=200.0,
                  k1=k1, k2=k2)  # fmt: skip

    xy, v = crop_pairs(pixels, circle.cx, circle.cy, half, field)
    start = camera([0, 0, 0, np.log(focal_px), circle.cx, circle.cy, 0, 0])
    u, _, vt = np.linalg.svd(start.pixels_to_bearings(xy).T @ v)
    R0 = u @ np.diag([1, 1, np.sign(np.linalg.det(u @ vt))]) @ vt
    det = detect_stars(pixels, threshold_sigma=5.0)
    inside = np.hypot(det.xy[:, 0] - circle.cx, det.xy[:, 1] - circle.cy) < circle.radius_px - 5
    found = det.xy[inside]
    tree = cKDTree(found)
    catalog_epoch = float(parse_utc(site[3]).decimalyear)
    catalog = load_catalog(None, mag_limit=6.0, epoch_year=catalog_epoch)

    def project(p, vectors):
        R = Rotation.from_rotvec(p[:3]).as_matrix() @ R0
        return camera(p).bearings_to_pixels(vectors @ R.T), R

    p = np.array([0, 0, 0, np.log(focal_px), circle.cx, circle.cy, 0, 0], dtype=float)
    for radius in ROUNDS_PX:
        R = project(p, catalog.vectors[:1])[1]
        c = catalog.vectors @ R.T
        rows = np.flatnonzero(camera(p).sees(c))
        d, j = tree.query(camera(p).bearings_to_pixels(c[rows]), distance_upper_bound=radius)
        near = np.isfinite(d)
        j, first = np.unique(j[near], return_index=True)
        stars, spots = catalog.vectors[rows[near][first]], found[j]
        p = least_squares(lambda q, v=stars, s=spots: (project(q, v)[0] - s).ravel(), p,
                          loss="soft_l1", f_scale=1.0).x  # fmt: skip
    residual = np.hypot(*(project(p, stars)[0] - spots).T)
    R = project(p, catalog.vectors[:1])[1]
    mount = mount_of(R, Site(*site))
    state = sky_state(pixels, R_cam_from_icrs=R, camera=camera(p), catalog=load_catalog(
        None, mag_limit=7.5, epoch_year=catalog_epoch), psf_sigma_px=det.psf_sigma_px,
        circle=circle, detected_xy=det.xy, site=Site(*site))  # fmt: skip
    return {
        "frame": path.name,
        "camera": camera(p).to_dict(),
        "R_cam_from_enu": mount.round(6).tolist(),
        "mag_limit": state.mag_limit,
        "site": dict(zip(("lat_deg", "lon_deg", "height_m", "utc"), site, strict=True)),
        "n_stars": len(spots),
        "median_residual_px": round(float(np.median(residual)), 2),
        "boresight_alt_deg": round(float(np.degrees(np.arcsin(mount[2, 2]))), 2),
    }


def main() -> None:
    folder = Path(os.environ.get("STARNAV_TUDO_FRAMES", ""))
    if not folder.is_dir():
        sys.exit("set STARNAV_TUDO_FRAMES to the folder of the tudo frames")
    out = {name: fit_camera(folder / f, site, half, focal, field)
           for name, (f, site, half, focal, field) in CAMERAS.items()}  # fmt: skip
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
