"""What the commands print: one-line JSON and the readable table of a solution."""

from __future__ import annotations

import json
import math
from typing import IO

from starnav.results import Solution


def to_json(obj: dict) -> str:
    """One line of JSON; NaN and infinities (e.g. an undetermined sigma) become null."""

    def clean(v):
        if isinstance(v, float) and not math.isfinite(v):
            return None
        if isinstance(v, dict):
            return {k: clean(x) for k, x in v.items()}
        if isinstance(v, list):
            return [clean(x) for x in v]
        return v

    return json.dumps(clean(obj), allow_nan=False)


def print_json(obj: dict) -> None:
    """Print ``obj`` as one line of JSON (``to_json``)."""
    print(to_json(obj))


def print_solution(s: Solution, *, file: IO[str] | None = None) -> None:
    """The readable table of a solution: attitude, quality, then one row per star."""
    print(
        f"solved: RA {s.ra_deg:.5f}°  Dec {s.dec_deg:+.5f}°  roll {s.roll_deg:.4f}°  "
        f"parity {s.parity:+d}",
        file=file,
    )
    print(
        f"  {s.n_matched}/{len(s.stars)} stars matched, rms {s.rms_px:.3f} px, "
        f"1σ boresight {s.sigma_boresight_arcsec:.2f}″ roll {s.sigma_roll_arcsec:.2f}″, "
        f"focal {s.focal_px:.2f} px (FOV {s.fov_deg:.4f}°)",
        file=file,
    )
    print(
        f"  false-match probability {s.false_match_probability:.1e}, {s.time_ms:.1f} ms, "
        f"catalog: {s.catalog}",
        file=file,
    )
    deep = s.star_table.deep  # the deep stage's columns, only when it ran
    extra = f" {'match_probability':>17} {'double':>6}" if deep else ""
    header = f"{'label':>8} {'x':>9} {'y':>9} {'catalog_id':>10} {'residual_px':>11}"
    print(header + extra, file=file)
    for m in s.stars:
        cid = "-" if m.catalog_id is None else str(m.catalog_id)
        res = "-" if m.residual_px is None else f"{m.residual_px:.3f}"
        row = f"{m.label:>8} {m.x:9.2f} {m.y:9.2f} {cid:>10} {res:>11}"
        if deep:
            prob = "-" if m.match_probability is None else f"{m.match_probability:.4f}"
            row += f" {prob:>17} {'yes' if m.double else '-':>6}"
        print(row, file=file)
