"""Fetch the real-image corpus (sources.json) from its upstream repositories, checked by SHA-256.

Every file is fetched as upstream committed it (byte for byte: nothing is re-encoded or
downscaled) from ``https://raw.githubusercontent.com/<repository>/<commit>/<path>`` and
checked against the SHA-256 recorded in ``sources.json``; a file that is already present and
intact is left alone. Usage, from the repository root::

    python tests/data/real/fetch.py                  # all files -> tests/data/real/files/
    python tests/data/real/fetch.py --redistributable  # only those whose licence allows it
    python tests/data/real/fetch.py --from DIR       # copy from a local folder instead
    python tests/data/real/fetch.py --check          # report what is present and intact

The tests and ``make_reference.py`` look for the files in ``$STARNAV_REAL_CORPUS``, then
``tests/data/real/files/``, then ``../shared/data/real/`` beside the repository (see
``find_corpus_dir``); a file absent from the folder found is skipped with the reason printed.
Standard library only.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shutil
import sys
import urllib.parse
import urllib.request
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCES = HERE / "sources.json"
DEFAULT_DIR = HERE / "files"
SHARED_DIR = HERE.parents[2].parent / "shared" / "data" / "real"
RAW_URL = "https://raw.githubusercontent.com/{repository}/{commit}/{path}"
TIMEOUT_S = 60


def sources() -> list[dict]:
    """The corpus table: one dict per file (name, repository, commit, path, sha256, ...)."""
    return json.loads(SOURCES.read_text())["files"]


def find_corpus_dir() -> Path | None:
    """The first folder holding corpus files: ``$STARNAV_REAL_CORPUS``, ``files/`` here,
    ``../shared/data/real`` beside the repository; None when none holds any."""
    names = {entry["name"] for entry in sources()}
    candidates = [os.environ.get("STARNAV_REAL_CORPUS"), DEFAULT_DIR, SHARED_DIR]
    for folder in candidates:
        if folder and Path(folder).is_dir() and any((Path(folder) / n).exists() for n in names):
            return Path(folder)
    return None


def sha256_file(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def intact(path: Path, entry: dict) -> bool:
    """The file exists with the recorded size and SHA-256."""
    return (
        path.is_file()
        and path.stat().st_size == entry["bytes"]
        and sha256_file(path) == entry["sha256"]
    )


def url_of(entry: dict) -> str:
    """The upstream raw URL of a file at its recorded commit."""
    return RAW_URL.format(
        repository=entry["repository"],
        commit=entry["commit"],
        path=urllib.parse.quote(entry["path"]),
    )


def fetch_one(entry: dict, out_dir: Path, local: Path | None) -> str:
    """Bring one file into ``out_dir``; returns what was done ("present", "copied",
    "downloaded") or raises SystemExit on a checksum mismatch."""
    target = out_dir / entry["name"]
    if intact(target, entry):
        return "present"
    partial = target.with_suffix(target.suffix + ".part")
    if local is not None:
        shutil.copyfile(local / entry["name"], partial)
        done = "copied"
    else:
        with urllib.request.urlopen(url_of(entry), timeout=TIMEOUT_S) as response:
            partial.write_bytes(response.read())
        done = "downloaded"
    if not intact(partial, entry):
        got = sha256_file(partial)
        partial.unlink()
        raise SystemExit(f"{entry['name']}: SHA-256 {got}, expected {entry['sha256']}")
    partial.replace(target)
    return done


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_DIR, help="folder to fill")
    parser.add_argument("--from", dest="local", type=Path, help="copy from this folder")
    parser.add_argument(
        "--redistributable", action="store_true", help="only files whose licence allows it"
    )
    parser.add_argument("--check", action="store_true", help="only report, fetch nothing")
    parser.add_argument("names", nargs="*", help="only these files")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    missing = 0
    for entry in sources():
        if args.names and entry["name"] not in args.names:
            continue
        if args.redistributable and not entry["redistributable"]:
            continue
        if args.check:
            ok = intact(args.out / entry["name"], entry)
            missing += not ok
            print(f"{'ok     ' if ok else 'MISSING'} {entry['name']}")
            continue
        print(f"{fetch_one(entry, args.out, args.local):10s} {entry['name']}", flush=True)
    return 1 if missing else 0


if __name__ == "__main__":
    sys.exit(main())
