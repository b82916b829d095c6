"""The celestial-fix sensitivity study (domain.md section 3) into docs/locate.md.

    python benchmarks/navigation/locate_study.py --trials 200

Monte Carlo on the real fix path; see ``starnav.studies.locate``. Also the time of a whole
``starnav locate`` (identification of three cameras and the fix) on the committed test
observations.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, ROOT, machine, replace_block, table_head, table_row
from starnav.navigation import locate, read_observation
from starnav.studies.locate import Setup, format_tables, plot_study, run_locate_study

DOC = DOCS / "locate.md"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    t0 = time.time()
    tables = run_locate_study(trials=args.trials, seed=args.seed)
    plot_study(tables, DOCS / "locate_study.png")
    setup = Setup()
    study = "\n".join(
        [
            f"Site lat {setup.lat_deg}°, lon {setup.lon_deg}°, {setup.utc} (the reference "
            f"epoch), heading {setup.heading_deg}°, level; three cameras 120° apart in azimuth "
            f"at 45° elevation, {setup.width} x {setup.width} px, 20° FOV unless stated, "
            f"Hipparcos Hp <= {setup.mag_limit:g}; {args.trials} trials per row, seed "
            f"{args.seed}. Position error: distance of the fix from the truth; azimuth: mean "
            "absolute heading error.",
            "",
            format_tables(tables),
            "",
            f"`python benchmarks/navigation/locate_study.py --trials {args.trials}`: "
            f"{time.time() - t0:.0f} s on {machine()}.",
        ]
    )
    replace_block(DOC, "study", study)
    times = []
    for path in sorted((ROOT / "tests" / "data" / "locate").glob("*.truth.json")):
        observation = read_observation(str(path).replace(".truth.json", ".json"))
        runs = [locate(observation).time_ms for _ in range(3)]
        times.append((path.name.removesuffix(".truth.json"), float(np.median(runs))))
    timing = "\n".join(
        [
            *table_head("observation", "ms (median of 3)"),
            *[table_row(name, f"{ms:.0f}") for name, ms in times],
            "",
            f"Identification of every camera and the fix, catalog loaded; {machine()}.",
        ]
    )
    replace_block(DOC, "timing", timing)
    print(study + "\n\n" + timing)


if __name__ == "__main__":
    main()
