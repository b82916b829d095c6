"""Where the tests' data live. Ours (references, tables we derived, generator scripts) are in
``tests/data``; files from other projects (photographs, the contest's star maps, the reference
frames) stay in ``../shared/data`` beside the repository and are never copied in. A test that
needs a shared file asks ``shared_file``: when the file is absent the test is skipped, saying
which file and where it was looked for."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
DATA = TESTS / "data"  # our own files
SHARED = ROOT.parent / "shared" / "data"
CONTEST = SHARED / "contest2019"
REFERENCE_FRAMES = SHARED / "reference_frames"
IMAGES = SHARED / "images"
ALLSKY = SHARED / "allsky"
REAL = SHARED / "real"
# the user's cache, read before conftest's session fixture points STARNAV_CACHE_DIR at a fresh
# folder (conftest imports this module first)
USER_CACHE_DIR = os.environ.get("STARNAV_CACHE_DIR")


def shared_file(path: Path) -> Path:
    """``path`` (a file under ``SHARED``) when it is there; else the calling test is skipped
    with the reason. Call it from a test or fixture, not at import."""
    if not path.is_file():
        where = path.parent if path.parent.is_dir() else SHARED
        pytest.skip(f"{path.name} is not in {where}: the shared test data go beside the "
                    "repository, in ../shared/data")  # fmt: skip
    return path


def reference_frames(name: str) -> list[dict]:
    """The frames of one ``../shared/data/reference_frames`` file (one JSON object a line)."""
    with shared_file(REFERENCE_FRAMES / name).open() as fh:
        return [json.loads(line) for line in fh]


# --- the four photographs of tests/data/images/reference.json (two peer solvers' answers) ---

PEER_REFERENCE = json.loads((DATA / "images" / "reference.json").read_text())["images"]
LYRA = "tetra3_2019-07-29T204726_Alt60_Azi135_Try1.png"  # 1024 x 768, 11.4°, 16 bit
SERPENS = "tetra3_2019-07-29T204726_Alt40_Azi-135_Try1.tif"  # the same camera, sparse
CYGNUS = "granasat_cisne_02sec.jpg"  # 1280 x 960, 27°, 8-bit JPEG of a distorting lens
POLARIS = "granasat_polar_05sec.jpg"
# reference.json's name -> the file in ../shared/data. The references were made from lossless
# re-encodings of the two tetra3 TIFFs (a deflate TIFF and a 16-bit PNG) that are no longer
# kept; upstream's own TIFFs in ../shared/data/real decode to the same pixels (their
# pixel_sha256, checked in tests/corpus/test_images.py).
PEER_FILES = {
    LYRA: REAL / "tetra3_Alt60_Azi135_Try1.tiff",
    SERPENS: REAL / "tetra3_Alt40_Azi-135_Try1.tiff",
    CYGNUS: IMAGES / CYGNUS,
    POLARIS: IMAGES / POLARIS,
}


def peer_image(name: str) -> Path:
    """The file of reference image ``name`` (a key of ``PEER_REFERENCE``); skips when absent."""
    return shared_file(PEER_FILES[name])


def as_png(path: Path, folder: Path) -> Path:
    """The pixels of image file ``path`` written losslessly as a PNG in ``folder`` (16 bit
    stays 16 bit): for tests of PNG input, made at test time from a shared file."""
    import numpy as np
    from PIL import Image

    out = Path(folder) / (path.stem + ".png")
    with Image.open(path) as img:
        pixels = np.asarray(img)
    Image.fromarray(pixels).save(out)
    with Image.open(out) as img:
        assert np.array_equal(np.asarray(img), pixels), f"{out.name}: not lossless"
    return out
