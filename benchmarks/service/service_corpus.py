"""The real-image corpus through a real nova client: astroquery's ``AstrometryNet`` against
``starnav serve``, each WCS compared with astrometry.net's own solve of the same file.

Starts the server (2 workers, a fresh data dir), uploads every file of the corpus
(tests/data/real/reference.json) that is in ../shared/data/real with astroquery's
``solve_from_image(force_image_upload=True)``, no hints, two clients at once, and compares the
sky at the image centre, FITS ((W+1)/2, (H+1)/2), of the WCS astroquery returns with that of
astrometry.net's (solve-field 0.93 with --crpix-center, Tycho-2 index: its CRVAL,
tests/data/real/reference.json).

    python benchmarks/service/service_corpus.py   # the block "service-corpus" of docs/service.md
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import warnings
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from astropy.coordinates import SkyCoord
from astropy.io import fits
from astropy.utils.exceptions import AstropyDeprecationWarning
from astropy.wcs import WCS, FITSFixedWarning

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repository: benchmarks.*
from benchmarks.harness import DOCS, ROOT, SHARED, machine, replace_block, table_head

sys.path.insert(0, str(ROOT / "tests"))
from service_helpers import Server

DOC = DOCS / "service.md"
CORPUS = ROOT / "tests" / "data" / "real"  # sources.json, reference.json
FILES = SHARED / "real"  # the photographs
TOLERANCE_ARCSEC = 60.0
TOLERANCE_PX = 2.0  # the wide fields (77″/px) differ from astrometry.net's TAN-SIP by ~1 px
SOLVE_TIMEOUT_S = 300.0


def centre(header: fits.Header, width: int, height: int) -> SkyCoord:
    """The sky at the image centre of a WCS header (with its SIP terms)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FITSFixedWarning)
        ra, dec = WCS(header, naxis=2).all_pix2world([[(width + 1) / 2, (height + 1) / 2]], 1)[0]
    return SkyCoord(ra, dec, unit="deg")


def solve(url: str, path: Path) -> tuple[fits.Header | None, float]:
    """astroquery's answer for one file (None when the job failed) and its wall time (s)."""
    from astroquery.astrometry_net import AstrometryNetClass

    client = AstrometryNetClass()
    client.URL, client.API_URL, client.TIMEOUT = url, url + "/api", SOLVE_TIMEOUT_S
    client.api_key = "any key"
    t0 = time.perf_counter()
    with warnings.catch_warnings():  # astroquery deprecates force_image_upload (kept working)
        warnings.simplefilter("ignore", AstropyDeprecationWarning)
        header = client.solve_from_image(str(path), force_image_upload=True, verbose=False,
                                         solve_timeout=SOLVE_TIMEOUT_S)  # fmt: skip
    return (header or None), time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clients", type=int, default=2)
    ap.add_argument("--no-doc", action="store_true", help="print only")
    args = ap.parse_args()
    reference = json.loads((CORPUS / "reference.json").read_text())["images"]
    names = [n for n in sorted(reference) if (FILES / n).is_file()]
    if not names:
        sys.exit(f"the corpus files are not here: {FILES}")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        server = Server(Path(tmp) / "data", workers=2).start()
        try:
            with ThreadPoolExecutor(args.clients) as pool:
                answers = list(pool.map(lambda n: solve(server.url, FILES / n), names))
        finally:
            server.stop()
    rows, counts = (
        [],
        {"both": 0, "within": 0, "only_an": 0, "only_starnav": 0, "neither": 0, "within_px": 0},
    )
    for name, (header, wall_s) in zip(names, answers, strict=True):
        ref = reference[name]
        w, h = ref["width"], ref["height"]
        an = ref["solved_by_reference"]
        scale = ref.get("scale_arcsec_per_px") or 1.0
        offset = None
        if header is not None and an:
            an_wcs = ref["astrometry_net"]["wcs"]  # solved with --crpix-center: CRVAL is it
            assert (an_wcs["CRPIX1"], an_wcs["CRPIX2"]) == ((w + 1) / 2, (h + 1) / 2), name
            an_centre = SkyCoord(an_wcs["CRVAL1"], an_wcs["CRVAL2"], unit="deg")
            offset = float(centre(header, w, h).separation(an_centre).arcsec)
            counts["both"] += 1
            counts["within"] += offset < TOLERANCE_ARCSEC
            counts["within_px"] += offset / scale < TOLERANCE_PX
        else:
            key = {(True, False): "only_an", (False, True): "only_starnav"}.get(
                (an, header is not None), "neither"
            )
            counts[key] += 1
        rows.append(
            f"| `{name}` | {'solved' if an else '-'} | {'solved' if header else '-'} | "
            f"{'' if offset is None else f'{offset:.1f}'} | "
            f"{'' if offset is None else f'{offset / scale:.2f}'} | "
            f"{wall_s:.1f} |"
        )
    n_an = sum(r["solved_by_reference"] for n, r in reference.items() if n in names)
    text = "\n".join([
        f"{len(names)} real photographs of ../shared/data/real uploaded by astroquery "
        f"(`AstrometryNet.solve_from_image`, force_image_upload, no hints) to `starnav serve "
        f"--workers 2`, {args.clients} clients at once; offset: the sky at the image centre of "
        f"the WCS astroquery got, from astrometry.net's solve of the same file.",
        "",
        *table_head(
            "file",
            "astrometry.net",
            "starnav via astroquery",
            "centre offset ″",
            "offset px",
            "wall s",
        ),
        *rows,
        "",
        f"astrometry.net solved {n_an}; starnav (through astroquery) solved {counts['both']} of "
        f"those, {counts['within']} within {TOLERANCE_ARCSEC:g}″ of astrometry.net's centre "
        f"and {counts['within_px']} within {TOLERANCE_PX:g} px; "
        f"{counts['only_an']} only astrometry.net solved, {counts['only_starnav']} only starnav, "
        f"{counts['neither']} neither.",
        "",
        f"{machine(load_at_end=True)}; `python "
        f"benchmarks/service/service_corpus.py`, {time.perf_counter() - t0:.0f} s.",
    ])  # fmt: skip
    print(text)
    if not args.no_doc:
        replace_block(DOC, "service-corpus", text)


if __name__ == "__main__":
    main()
