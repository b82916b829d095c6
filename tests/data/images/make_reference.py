"""The reference answers (reference.json) of four real star images, from two peer solvers.

Run from the repository root with the system Python (numpy and Pillow)::

    python tests/data/images/make_reference.py reference

The images are not in this repository: they are upstream's files in ../shared/data beside it
(``SHARED_FILES``: the two GranaSAT JPEGs in ``images/``, the two tetra3 TIFFs in ``real/``).
Their names here (the keys of ``IMAGES`` and of reference.json) are those of the copies once
kept in this folder: the JPEGs byte for byte, the 16-bit TIFFs re-encoded losslessly (a deflate
TIFF and a 16-bit PNG) with the same decoded pixels as upstream's TIFFs.

``reference`` runs two peer solvers on every image, each from the image with its
own star extraction, each inside its own virtual environment (``$STARNAV_CACHE_DIR/venvs/<peer>``,
default ``~/.cache/starnav``: ``pip install cedar-solve==0.5.1`` and ``pip install
tetra3rs==0.14.0``, as ``benchmarks/peers/peers.py`` makes them). This file is also the worker
that runs there (``worker cedar|tetra3rs``): it imports numpy, the peer and, for cedar, the
parity test of ``benchmarks/peers/peer_cedar.py``, and reads the images as ``.npy`` arrays
decoded here with Pillow.

* cedar-solve: ``Tetra3.solve_from_image`` (its ``get_centroids_from_image`` with defaults),
  shipped database (Hipparcos to magnitude 8, 10-30°, proper motion to 2024.0), ``distortion``
  0, FOV unknown (``fov_estimate`` None) and given (the nominal FOV).
* tetra3rs: ``extract_centroids`` (defaults) then ``solve_from_centroids`` with the nominal FOV
  (it needs an estimate), its out-of-the-box database: Gaia DR3 + Hipparcos bundled with it,
  10-30°, proper motion to 2025.0, made by ``benchmarks/peers/peer_tetra3rs.py build-stock`` if
  absent.

Conventions (both checked in ``benchmarks/peers/peer_cedar.py`` / ``peer_tetra3rs.py``): pixel
origin at the top-left corner for both (cedar: (y, x) with (0.5, 0.5) the top-left pixel centre;
tetra3rs: origin at the image centre, checked here on a synthetic star); RA/Dec are those of the
image centre (W/2, H/2), FOV the horizontal one. Roll is converted to starnav's (position angle
of image up, -y, from North through East): cedar's ``Roll`` is North counter-clockwise from up,
starnav roll = -Roll mod 360 (parity +1; cedar reports no parity: it is taken from the
handedness of its matched stars); tetra3rs's ``roll_deg`` is the position angle of image down,
starnav roll = roll_deg + 180 mod 360, and is checked against the roll computed here from its
rotation matrix. The reference is the mean of cedar (FOV unknown) and tetra3rs: boresight the
normalised sum of the two unit vectors, roll their circular mean, FOV their mean.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[2]
SHARED = ROOT.parent / "shared" / "data"
# name -> upstream's file in ../shared/data (for the tetra3 frames: the TIFF whose pixels the
# copy once kept here re-encoded)
TETRA3 = "tetra3_2019-07-29T204726_"
SHARED_FILES = {
    f"{TETRA3}Alt40_Azi-135_Try1.tif": SHARED / "real" / "tetra3_Alt40_Azi-135_Try1.tiff",
    f"{TETRA3}Alt60_Azi135_Try1.png": SHARED / "real" / "tetra3_Alt60_Azi135_Try1.tiff",
    "granasat_cisne_02sec.jpg": SHARED / "images" / "granasat_cisne_02sec.jpg",
    "granasat_polar_05sec.jpg": SHARED / "images" / "granasat_polar_05sec.jpg",
}
REFERENCE = HERE / "reference.json"

ESA = {
    "repository": "esa/tetra3",
    "licence": "CC BY-SA 3.0 IGO, credit 'ESA/Gustav Pettersson' (esa/tetra3 is Apache-2.0)",
    "camera": "FLIR Blackfly S BFS-U3-31S4M-C (Sony IMX265, binned 2x2), Fujifilm HF35XA-5M 35 mm"
    " f/1.9",
    "taken": "2019-07-29T20:47:26",
    "nominal_fov_deg": 11.4,
    "nominal_fov_source": "esa/tetra3 README.rst: '11.4 degrees FOV'",
}
GRANASAT = {
    "repository": "granasat/startrackerpy",
    "commit": "2f1c97c255d9d55dbc467779e95e23d7e1120f21",
    "licence": "MIT, Copyright (c) 2020 Iris García de Sebastián",
    "camera": "The Imaging Source DMK 41BU02 (1280 x 960, Sony ICX205AL), lens not documented",
    "taken": "2020 (added to the repository 2020-08/09)",
    "nominal_fov_deg": 27.0,
    "nominal_fov_source": "lens undocumented: the peers' solved FOV (27.03-27.09°), rounded",
}

# name (of the copy once kept here) -> where it comes from and how it was kept
IMAGES = {
    "tetra3_2019-07-29T204726_Alt40_Azi-135_Try1.tif": {
        **ESA,
        "path": "examples/data/2019-07-29T204726_Alt40_Azi-135_Try1.tiff",
        "commit": "26aa2fefc9d0f8a2fcd0aa9949fdba89154cba84",
        "git_blob": "6189293486a2555d99dc45b8bf87a9d869e65595",
        "vendored_as": "16-bit TIFF, re-encoded losslessly with deflate compression",
    },
    "tetra3_2019-07-29T204726_Alt60_Azi135_Try1.png": {
        **ESA,
        "path": "test_data/2019-07-29T204726_Alt60_Azi135_Try1.tiff",
        "commit": "c8324f449f0fa2ede16cd07484032d543567c4c2",
        "git_blob": "279db925bad2077494cce5289a955726b8e03186",
        "vendored_as": "16-bit grayscale PNG, re-encoded losslessly from the TIFF",
    },
    "granasat_cisne_02sec.jpg": {
        **GRANASAT,
        "path": "startrackerpy/server/startracker/test_images/cisne_02sec.jpg",
        "git_blob": "3d1f4c7d643358e705823e8635f9391f18de2280",
        "vendored_as": "the upstream file, byte for byte",
    },
    "granasat_polar_05sec.jpg": {
        **GRANASAT,
        "path": "startrackerpy/server/startracker/test_images/polar_05sec.jpg",
        "git_blob": "1e67148d47d8b667b61261e70fbb9186fcf23e1f",
        "vendored_as": "the upstream file, byte for byte",
    },
}


# ---------------------------------------------------------------- worker (inside a peer's venv)


def _unit(ra_deg, dec_deg) -> np.ndarray:
    ra, dec = np.radians(ra_deg), np.radians(dec_deg)
    return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], axis=-1)


def _worker_cedar(files: list[str], fov_deg: float | None) -> None:
    import tetra3
    from PIL import Image

    sys.path.insert(0, str(ROOT / "benchmarks" / "peers"))  # the cedar adapter's conventions
    from peer_cedar import parity_of_matches, quiet

    t3 = tetra3.Tetra3(load_database=None)
    quiet(t3)
    t3.load_database("default_database")
    for name in files:
        pixels = np.load(name)
        height, width = pixels.shape
        result = t3.solve_from_image(
            Image.fromarray(pixels), fov_estimate=fov_deg, return_matches=True
        )
        codes = ("MATCH_FOUND", "NO_MATCH", "TIMEOUT", "CANCELLED", "TOO_FEW")
        status = {getattr(tetra3.tetra3, c): c for c in codes}.get(result.get("status"))
        out = {"status": status or str(result.get("status"))}
        if result.get("RA") is not None:
            parity = parity_of_matches(result, width, height)
            out.update(
                RA=float(result["RA"]),
                Dec=float(result["Dec"]),
                Roll=float(result["Roll"]),
                FOV=float(result["FOV"]),
                RMSE_arcsec=float(result["RMSE"]),
                Matches=int(result["Matches"]),
                Prob=float(result["Prob"]),
                T_extract_ms=float(result["T_extract"]),
                T_solve_ms=float(result["T_solve"]),
                parity_from_matches=parity,
            )
        print(json.dumps(out), flush=True)


def _worker_tetra3rs(files: list[str], fov_deg: float, database: str) -> None:
    import tetra3rs

    # pixel origin: a star centred on pixel (row 100, col 200) is at starnav (200.5, 100.5)
    yy, xx = np.mgrid[0:300, 0:400] + 0.5
    star = 1000 * np.exp(-((xx - 200.5) ** 2 + (yy - 100.5) ** 2) / 4.5) + 100
    noise = np.random.default_rng(1).integers(0, 3, star.shape)
    found = tetra3rs.extract_centroids((star + noise).astype(np.uint16)).centroids[0]
    if abs(found.x + 200 - 200.5) > 0.01 or abs(found.y + 150 - 100.5) > 0.01:
        raise SystemExit(f"tetra3rs pixel origin not as assumed: {found.x}, {found.y}")
    db = tetra3rs.SolverDatabase.load_from_file(database)
    for name in files:
        pixels = np.load(name)
        height, width = pixels.shape
        extraction = tetra3rs.extract_centroids(pixels)
        result = db.solve_from_centroids(
            extraction.centroids, fov_estimate_deg=fov_deg, image_width=width, image_height=height
        )
        out = {"status": str(result.status), "n_centroids": len(extraction.centroids)}
        if result:
            out.update(
                ra_deg=float(result.ra_deg),
                dec_deg=float(result.dec_deg),
                roll_deg=float(result.roll_deg),
                parity_flip=bool(result.parity_flip),
                fov_deg=float(result.fov_deg),
                num_matches=int(result.num_matches),
                rmse_arcsec=float(result.rmse_arcsec),
                probability=float(result.probability),
                rotation_matrix_icrs_to_camera=np.asarray(
                    result.rotation_matrix_icrs_to_camera
                ).tolist(),
            )
        print(json.dumps(out), flush=True)


# ---------------------------------------------------------------- driver (system Python)


def sha256_file(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def decode(path: Path) -> np.ndarray:
    """The pixels as Pillow decodes them: a 2-D uint8 or uint16 array."""
    from PIL import Image

    with Image.open(path) as img:
        pixels = np.asarray(img)
    if pixels.ndim != 2:
        raise SystemExit(f"{path.name}: expected a one-channel image, got shape {pixels.shape}")
    return pixels


def pixel_sha256(pixels: np.ndarray) -> str:
    """SHA-256 of the pixel values as little-endian integers, row by row."""
    return hashlib.sha256(pixels.astype(pixels.dtype.newbyteorder("<")).tobytes()).hexdigest()


def cache_root() -> Path:
    return Path(os.environ.get("STARNAV_CACHE_DIR") or Path.home() / ".cache" / "starnav")


def run_worker(python: Path, args: list[str]) -> list[dict]:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.run(
        [str(python), "-I", str(Path(__file__).resolve()), "worker", *args],
        capture_output=True,
        text=True,
        env=env,
        check=False,
    )
    if proc.returncode:
        raise SystemExit(f"worker {args[0]} failed:\n{proc.stderr}")
    return [json.loads(line) for line in proc.stdout.splitlines() if line.startswith("{")]


def position_angle_of_up_deg(r_cam_from_icrs: np.ndarray) -> float:
    """starnav roll from a rotation whose rows are the camera axes (x right, y down) in ICRS."""
    up, boresight = -r_cam_from_icrs[1], r_cam_from_icrs[2]
    ra = np.arctan2(boresight[1], boresight[0])
    dec = np.arcsin(np.clip(boresight[2], -1.0, 1.0))
    north = np.array([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)])
    east = np.array([-np.sin(ra), np.cos(ra), 0.0])
    return float(np.degrees(np.arctan2(up @ east, up @ north)) % 360.0)


def separation_arcsec(a: dict, b: dict) -> float:
    u, v = _unit(a["ra_deg"], a["dec_deg"]), _unit(b["ra_deg"], b["dec_deg"])
    return float(np.degrees(np.arctan2(np.linalg.norm(np.cross(u, v)), u @ v)) * 3600.0)


def roll_difference_deg(a: float, b: float) -> float:
    return float((a - b + 180.0) % 360.0 - 180.0)


def attitude(answer: dict) -> np.ndarray:
    """R_cam_from_icrs (rows: camera x right, y down, z boresight in ICRS) of an answer."""
    z = _unit(answer["ra_deg"], answer["dec_deg"])
    ra, dec, roll = np.radians([answer["ra_deg"], answer["dec_deg"], answer["roll_deg"]])
    north = np.array([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)])
    east = np.array([-np.sin(ra), np.cos(ra), 0.0])
    y = -(np.cos(roll) * north + np.sin(roll) * east)
    x = np.cross(y, z) if answer["parity"] > 0 else np.cross(z, y)
    return np.array([x, y, z])


def twist_deg(a: dict, b: dict) -> float:
    """Rotation about the boresight between two answers, from their relative rotation (the
    difference of position angles is unstable near the celestial poles)."""
    d = attitude(a) @ attitude(b).T
    return float(np.degrees(np.arctan2(d[1, 0] - d[0, 1], d[0, 0] + d[1, 1])))


def from_cedar(raw: dict, mode: str) -> dict:
    if raw.get("RA") is None:
        return {"solver": "cedar-solve 0.5.1", "mode": mode, "status": raw["status"]}
    parity = raw["parity_from_matches"]
    roll = (-raw["Roll"]) % 360.0 if parity > 0 else raw["Roll"] % 360.0
    return {
        "solver": "cedar-solve 0.5.1",
        "mode": mode,
        "status": raw["status"],
        "ra_deg": raw["RA"],
        "dec_deg": raw["Dec"],
        "roll_deg": roll,
        "parity": parity,
        "fov_deg": raw["FOV"],
        "n_matched": raw["Matches"],
        "rms_arcsec": raw["RMSE_arcsec"],
        "raw": {k: raw[k] for k in ("RA", "Dec", "Roll", "FOV", "Prob")},
    }


def from_tetra3rs(raw: dict, mode: str) -> dict:
    if "ra_deg" not in raw:
        return {"solver": "tetra3rs 0.14.0", "mode": mode, "status": raw["status"]}
    parity = -1 if raw["parity_flip"] else 1
    roll = (raw["roll_deg"] + 180.0) % 360.0
    matrix = np.asarray(raw["rotation_matrix_icrs_to_camera"])
    if parity < 0:  # tetra3rs fits a proper rotation to x-negated pixels
        matrix = matrix * np.array([[-1.0], [1.0], [1.0]])
    if abs(roll_difference_deg(position_angle_of_up_deg(matrix), roll)) > 1e-6:
        raise SystemExit(f"tetra3rs roll {roll} disagrees with its rotation matrix")
    return {
        "solver": "tetra3rs 0.14.0",
        "mode": mode,
        "status": raw["status"],
        "ra_deg": raw["ra_deg"],
        "dec_deg": raw["dec_deg"],
        "roll_deg": roll,
        "parity": parity,
        "fov_deg": raw["fov_deg"],
        "n_matched": raw["num_matches"],
        "rms_arcsec": raw["rmse_arcsec"],
        "raw": {k: raw[k] for k in ("ra_deg", "dec_deg", "roll_deg", "parity_flip", "fov_deg")},
    }


def combine(a: dict, b: dict) -> dict:
    """The reference: mean boresight (unit vectors), circular mean roll, mean FOV."""
    if a["parity"] != b["parity"]:
        raise SystemExit(f"peers disagree on parity: {a['parity']} vs {b['parity']}")
    boresight = _unit(a["ra_deg"], a["dec_deg"]) + _unit(b["ra_deg"], b["dec_deg"])
    boresight /= np.linalg.norm(boresight)
    rolls = np.radians([a["roll_deg"], b["roll_deg"]])
    roll = np.degrees(np.arctan2(np.sin(rolls).sum(), np.cos(rolls).sum())) % 360.0
    return {
        "ra_deg": round(float(np.degrees(np.arctan2(boresight[1], boresight[0])) % 360.0), 5),
        "dec_deg": round(float(np.degrees(np.arcsin(boresight[2]))), 5),
        "roll_deg": round(float(roll), 4),
        "parity": a["parity"],
        "fov_deg": round(0.5 * (a["fov_deg"] + b["fov_deg"]), 4),
    }


def cmd_reference(args) -> None:
    venvs = cache_root() / "venvs"
    cedar_py = venvs / "cedar-solve" / "bin" / "python"
    t3rs_py = venvs / "tetra3rs" / "bin" / "python"
    t3rs_db = cache_root() / "peers" / "tetra3rs" / "stock.bin"
    if not t3rs_db.exists():
        builder = ROOT / "benchmarks" / "peers" / "peer_tetra3rs.py"
        cmd = [str(t3rs_py), "-I", str(builder), "build-stock", "--out", str(t3rs_db)]
        subprocess.run(cmd, check=True)
    out: dict = {
        "about": (
            "Reference answers for four images of ../shared/data, in starnav's conventions (pixel"
            " origin at the top-left corner, boresight = image centre W/2, H/2, roll = position"
            " angle of image up (-y) from North through East, fov_deg horizontal). Reference ="
            " mean of cedar-solve (FOV unknown) and tetra3rs (nominal FOV given), each solving"
            " from the image with its own star extraction; 'peers' has every run, 'agreement'"
            " how far they are apart. Made by make_reference.py (read its docstring)."
        ),
        "images": {},
    }
    with tempfile.TemporaryDirectory() as tmp:
        for name, info in IMAGES.items():
            path = SHARED_FILES[name]
            pixels = decode(path)
            npy = Path(tmp) / (name + ".npy")
            np.save(npy, pixels)
            fov = info["nominal_fov_deg"]
            cedar_unknown = from_cedar(run_worker(cedar_py, ["cedar", str(npy)])[0], "fov unknown")
            cedar_given = from_cedar(
                run_worker(cedar_py, ["cedar", "--fov-deg", str(fov), str(npy)])[0],
                f"fov_estimate {fov}",
            )
            t3rs = from_tetra3rs(
                run_worker(
                    t3rs_py, ["tetra3rs", "--db", str(t3rs_db), "--fov-deg", str(fov), str(npy)]
                )[0],
                f"fov_estimate_deg {fov}",
            )
            peers = {"cedar_fov_unknown": cedar_unknown, "cedar_fov_given": cedar_given}
            peers["tetra3rs_fov_given"] = t3rs
            reference = combine(cedar_unknown, t3rs)
            agreement = {
                f"{k}_vs_reference": {
                    "boresight_arcsec": round(separation_arcsec(p, reference), 1),
                    "roll_deg": round(roll_difference_deg(p["roll_deg"], reference["roll_deg"]), 4),
                    "twist_deg": round(twist_deg(p, reference), 4),
                    "fov_percent": round(100 * (p["fov_deg"] / reference["fov_deg"] - 1), 3),
                }
                for k, p in peers.items()
                if "ra_deg" in p
            }
            agreement["cedar_vs_tetra3rs_boresight_arcsec"] = round(
                separation_arcsec(cedar_unknown, t3rs), 1
            )
            out["images"][name] = {
                **reference,
                "nominal_fov_deg": fov,
                "source": "mean of cedar-solve (FOV unknown) and tetra3rs (FOV given)",
                "file": {
                    "bytes": path.stat().st_size,
                    "sha256": sha256_file(path),
                    "width": int(pixels.shape[1]),
                    "height": int(pixels.shape[0]),
                    "dtype": str(pixels.dtype),
                    "pixel_sha256": pixel_sha256(pixels),
                    "identical_to_upstream": "bytes",  # the shared files are upstream's
                },
                "provenance": {k: v for k, v in info.items() if k != "nominal_fov_deg"},
                "agreement": agreement,
                "peers": peers,
            }
            print(name, json.dumps(reference), json.dumps(agreement), flush=True)
    REFERENCE.write_text(json.dumps(out, indent=1, ensure_ascii=False) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="cmd", required=True)
    sub.add_parser("reference", help="run the peers, write reference.json")
    p = sub.add_parser("worker", help="(inside a peer's venv) solve .npy images")
    p.add_argument("peer", choices=["cedar", "tetra3rs"])
    p.add_argument("--fov-deg", type=float)
    p.add_argument("--db")
    p.add_argument("files", nargs="+")
    args = parser.parse_args()
    if args.cmd == "reference":
        cmd_reference(args)
    elif args.peer == "cedar":
        _worker_cedar(args.files, args.fov_deg)
    else:
        _worker_tetra3rs(args.files, args.fov_deg, args.db)


if __name__ == "__main__":
    sys.exit(main())
