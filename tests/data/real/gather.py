"""Gather a real-image set into a folder from snapshots of the repositories it names.

The image files are other projects' files and are not in this repository; the manifests
(``sources.json``, ``allsky_manifest.json``, ``narrow_heldback.json``) say where each comes
from (repository, commit, path, git blob id, SHA-256). With a snapshot of each repository as
a bare git directory (``MIRRORS/owner+name/repo``, or ``.../repo/.git``), this writes every
file of a manifest into OUT under its ``name``, taken by its git blob id (else
``commit:path``) and kept only when its SHA-256 matches::

    python tests/data/real/gather.py tests/data/real/sources.json /work/corpus/all
    STARNAV_REAL_CORPUS=/work/corpus/all python benchmarks/peers/real_images.py ...

A file whose repository is missing or whose bytes differ is reported by name, one line
each, with the repositories still to fetch; the exit status is 1 when any file is missing.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import subprocess
import sys
from pathlib import Path

DEFAULT_MIRRORS = Path("/work/.mirror")


def git_dir(mirrors: Path, repository: str) -> Path | None:
    """The git directory of a repository snapshot, or None when it is not there."""
    root = mirrors / repository.replace("/", "+") / "repo"
    for candidate in (root / ".git", root):
        if (candidate / "HEAD").is_file():
            return candidate
    return None


def blob_bytes(gdir: Path, entry: dict) -> bytes | None:
    """The file's bytes from the snapshot: by blob id, else by commit and path."""
    for spec in (entry.get("git_blob"), f"{entry['commit']}:{entry['path']}"):
        if not spec:
            continue
        run = subprocess.run(
            ["git", f"--git-dir={gdir}", "cat-file", "blob", spec],
            capture_output=True,
            check=False,
        )
        if run.returncode == 0:
            return run.stdout
    return None


def gather(entries: list[dict], out: Path, mirrors: Path) -> tuple[int, list[str], set[str]]:
    """Write each entry's file into ``out``; returns (written, problems, missing repos)."""
    out.mkdir(parents=True, exist_ok=True)
    written, problems, missing = 0, [], set()
    for entry in entries:
        target = out / entry["name"]
        if target.is_file() and hashlib.sha256(target.read_bytes()).hexdigest() == entry["sha256"]:
            written += 1
            continue
        gdir = git_dir(mirrors, entry["repository"])
        if gdir is None:
            missing.add(entry["repository"])
            problems.append(f"{entry['name']}: no snapshot of {entry['repository']}")
            continue
        data = blob_bytes(gdir, entry)
        if data is None:
            problems.append(f"{entry['name']}: not in the snapshot of {entry['repository']}")
        elif hashlib.sha256(data).hexdigest() != entry["sha256"]:
            problems.append(f"{entry['name']}: SHA-256 differs from the manifest")
        else:
            target.write_bytes(data)
            written += 1
    return written, problems, missing


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("manifest", type=Path, help="sources.json, allsky_manifest.json, ...")
    parser.add_argument("out", type=Path, help="the folder to write the files into")
    parser.add_argument("--mirrors", type=Path, default=DEFAULT_MIRRORS)
    args = parser.parse_args()
    entries = json.loads(args.manifest.read_text())["files"]
    written, problems, missing = gather(entries, args.out, args.mirrors)
    for line in problems:
        print(line, file=sys.stderr)
    if missing:
        print("repositories to fetch: " + " ".join(sorted(missing)), file=sys.stderr)
    print(f"{written} of {len(entries)} files in {args.out}")
    sys.exit(1 if problems else 0)


if __name__ == "__main__":
    main()
