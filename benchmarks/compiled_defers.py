"""How often the compiled path hands a frame to the numpy path ("defers"), per scenario.

    python benchmarks/compiled_defers.py

The compiled identification defers when a one-to-one pairing has more than 12 linked
candidate pairs; the compiled fit also when Gauss-Newton does not lower the cost (where the
numpy path turns to Levenberg-Marquardt). A deferred frame gets the numpy path's answer, at
the numpy path's speed. Frames: whole-sky, Hipparcos Hp <= 6, seed 9.
"""

from __future__ import annotations

import numpy as np

from lost_in_space import machine
from starnav import compiled
from starnav.api import get_database
from starnav.camera import Camera
from starnav.catalog import load_catalog
from starnav.identify import MatchSettings
from starnav.simulate import simulate_frame

# (FOV deg, width px, noise px, false stars, missing fraction, frames)
SCENARIOS = [
    (12.0, 512, 0.5, 2, 0.1, 2000),
    (12.0, 512, 1.0, 2, 0.1, 1000),
    (20.0, 1024, 0.2, 0, 0.0, 500),
]


def main() -> None:
    catalog = load_catalog(None, mag_limit=6.0)
    print(
        "| FOV | noise px | false stars | missing | frames | identification deferred | "
        "fit deferred (of those identified) |"
    )
    print("|---|---|---|---|---|---|---|")
    for fov, width, noise, false, missing, n in SCENARIOS:
        camera = Camera.from_fov(fov, width)
        database = get_database(catalog, camera)
        settings = MatchSettings.for_focal(noise, camera.focal_px)
        rng = np.random.default_rng(9)
        frames = deferred_id = deferred_fit = identified = 0
        for _ in range(n):
            f = simulate_frame(
                catalog, camera, noise_px=noise, false_stars=false, missing_frac=missing, seed=rng
            )
            if len(f.xy) < 3:
                continue
            frames += 1
            bearings = camera.pixels_to_bearings(f.xy)
            order = np.argsort(-f.brightness, kind="stable")
            outcome = compiled.identify(bearings, order, database, settings)
            if outcome is None:
                deferred_id += 1
                continue
            if outcome.identification is None:
                continue
            identified += 1
            done = compiled.conclude(
                outcome.identification, f.xy, camera, database, settings,
                sigma_px=noise, min_matched_fraction=0.5,
            )  # fmt: skip
            deferred_fit += done is None
        print(
            f"| {fov:g}° / {width} px | {noise:g} | {false} | {missing:g} | {frames} | "
            f"{deferred_id} | {deferred_fit} of {identified} |"
        )
    print(f"\n{machine()}; `python benchmarks/compiled_defers.py`")


if __name__ == "__main__":
    main()
