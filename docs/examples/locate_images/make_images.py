"""Make this folder's example: three 20° star cameras on a platform near Zürich, rendered as
image files, and the observation file that `starnav locate` reads them from.

    python docs/examples/locate_images/make_images.py
    starnav locate docs/examples/locate_images/obs.json

The platform (truth.json) stands at 47.37° N, 8.54° E, heading 30°, pitched up 1°, on
2025-06-01 at 22:00:00 UTC, under a standard atmosphere (refraction on). Its cameras look out at
45° elevation, 120° apart in azimuth, 512 x 512 px. The stars are placed by the locate
simulator (``starnav.navigation.simulate``: apparent places in the local frame, refracted) and
drawn by the renderer (pixel-integrated Gaussian PSF, sky, photon and read noise). Each camera
shows another way of giving an image:

- fore.fits.gz: FITS, 16 bit, its time in DATE-OBS (UTC); its lens by ``fov_deg``.
- right.jpg: JPEG, 8 bit, its time in EXIF DateTimeOriginal, the camera clock's local time
  (UTC+2, hence ``utc_offset_hours``); its lens in the camera file lens.json.
- left.png: PNG, 8 bit, no time; neither lens nor FOV given: the field of view is searched.

obs.json has no ``utc``: it comes from the two images that record a time.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
from astropy.io import fits
from PIL import Image

from starnav.camera import Camera, save_camera
from starnav.navigation.simulate import render_views, simulate_observation
from starnav.simulate.render import RenderSettings

HERE = Path(__file__).resolve().parent
TRUTH = {"lat_deg": 47.37, "lon_deg": 8.54, "heading_deg": 30.0, "pitch_deg": 1.0}
UTC = "2025-06-01T22:00:00Z"
WIDTH = 512
EXIF_IFD, DATE_TIME_ORIGINAL = 0x8769, 36867


def main() -> None:
    sky = simulate_observation(
        **TRUTH, utc=UTC, width=WIDTH, pressure_hpa=1013.25, temperature_c=15.0
    )
    sixteen = RenderSettings(seed=1)
    eight = replace(sixteen, bit_depth=8, gain_e_per_adu=4.0)
    fore = render_views(sky, sixteen, seed=1)[0]
    right, left = render_views(sky, eight, seed=1)[1:]
    fits.PrimaryHDU(fore, header=fits.Header({"DATE-OBS": "2025-06-01T22:00:00.0"})).writeto(
        HERE / "fore.fits.gz", overwrite=True
    )
    exif = Image.Exif()
    exif.get_ifd(EXIF_IFD)[DATE_TIME_ORIGINAL] = "2025:06:02 00:00:00"  # local time, UTC+2
    Image.fromarray(right).save(HERE / "right.jpg", quality=92, exif=exif)
    Image.fromarray(left).save(HERE / "left.png", optimize=True)
    save_camera(HERE / "lens.json", Camera.from_fov(20.0, WIDTH))
    mounts = [{"azimuth_deg": az, "elevation_deg": 45} for az in (0, 120, 240)]
    cameras = [
        {"name": "fore", **mounts[0], "fov_deg": 20, "image": "fore.fits.gz"},
        {
            "name": "right",
            **mounts[1],
            "camera": "lens.json",
            "image": "right.jpg",
            "utc_offset_hours": 2,
        },
        {"name": "left", **mounts[2], "image": "left.png"},
    ]
    gravity = (np.round(sky.observation.gravity_body, 9) + 0.0).tolist()  # no -0.0
    obs = {"gravity_body": gravity, "cameras": cameras}
    (HERE / "obs.json").write_text(json.dumps(obs, indent=2) + "\n")
    truth = {"utc": UTC, **TRUTH, "azimuth_deg": TRUTH["heading_deg"]}
    (HERE / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")


if __name__ == "__main__":
    main()
