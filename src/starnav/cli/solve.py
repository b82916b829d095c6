"""``starnav solve``: image files (FITS, PNG, JPEG, TIFF) to verified attitudes, with the field
of view unknown, roughly known or calibrated; optionally WCS headers, FITS copies with the WCS
and pictures. One file prints its answer; many files (or a directory, ``--jsonl``, ``--track``)
are a batch (``starnav.pipeline.image_batch``): one line per file, a progress bar and a summary."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from starnav.cli.common import (
    EXIT_BAD_INPUT,
    EXIT_NOT_SOLVED,
    EXIT_OK,
    Subparsers,
    add_dask,
    check_parent_dir,
    positive_int,
)
from starnav.cli.field import (
    add_image_solve_options,
    check_fov,
    image_solve_options,
    mounted_dict,
    solve_mounted,
)
from starnav.cli.output import print_json, print_solution, to_json
from starnav.errors import StarnavError

if TYPE_CHECKING:
    from starnav.pipeline.image import ImageSolveResult
WCS_SUFFIXES = (".fits", ".fit", ".fts", ".wcs")


def add_parser(subparsers: Subparsers) -> None:
    """The ``solve`` command and its options."""
    p = subparsers.add_parser(
        "solve", help="solve image files (FITS, PNG, JPEG, TIFF, BMP, ...): FOV may be unknown"
    )
    p.add_argument("images", nargs="+", metavar="IMAGE", help="image files or directories of them")
    add_image_solve_options(p)
    p.add_argument(
        "--wcs",
        metavar="FITS",
        help="write a FITS WCS header here (the lens model's projection: pinhole TAN or "
        "TAN-SIP, equidistant ARC, stereographic STG, equisolid ZEA, orthographic SIN, "
        "kannala-brandt ARC-SIP); a directory for a batch (NAME.wcs per file)",
    )
    p.add_argument(
        "--new-fits",
        metavar="FITS",
        help="write the solved image as FITS with the WCS in its header (like astrometry.net's "
        ".new; a FITS image keeps its data and header cards); a directory for a batch "
        "(NAME.new.fits)",
    )
    p.add_argument(
        "--annotate",
        metavar="PNG",
        help="draw the image into this PNG: solved, the stars identified; not solved, the "
        "detections and the reason; a directory for a batch (NAME.png)",
    )
    batch = p.add_argument_group("many files")
    batch.add_argument(
        "--workers", type=positive_int, help="processes for a batch (default: all cores)"
    )
    add_dask(batch, "the batch")
    batch.add_argument("--jsonl", metavar="FILE", help="write one JSON line per file here")
    batch.add_argument(
        "--track",
        action="store_true",
        help="the files are a sequence: each solved frame's attitude and camera are the next "
        "one's prior (tracking), falling back to lost in space",
    )
    p.add_argument("--json", action="store_true", help="print JSON (one line per file in a batch)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    """One file: read, detect, solve, write the outputs, print. Many: ``run_batch``."""
    check_fov(args, args.lens)
    paths = [Path(p) for p in args.images]
    if len(paths) > 1 or paths[0].is_dir() or args.jsonl or args.track or args.dask:
        return run_batch(args, paths)
    _check_file_outputs(args)
    from starnav.detect.header import fits_hints
    from starnav.detect.read import read_image
    from starnav.pipeline.image import write_outputs

    t0 = time.perf_counter()
    pixels = read_image(paths[0])
    read_ms = (time.perf_counter() - t0) * 1e3
    options = image_solve_options(args)
    options.setdefault("hints", fits_hints(paths[0]))
    res, mounted = solve_mounted(args, paths[0], pixels, options, read_ms)
    outputs = {"wcs": args.wcs, "new_fits": args.new_fits, "annotate": args.annotate}
    write_outputs({k: v and Path(v) for k, v in outputs.items()}, paths[0], pixels, res)
    if res.solution is None and (args.wcs or args.new_fits):
        print("starnav solve: not solved, no WCS written", file=sys.stderr)
    if args.json:
        print_json(mounted_dict(res, mounted, args.images[0]))
    else:
        _print_text(res)
    return EXIT_OK if res.solution else EXIT_NOT_SOLVED


def _check_file_outputs(args: argparse.Namespace) -> None:
    """The output files of one image: names and directories, before any work."""
    checks = (
        ("wcs", WCS_SUFFIXES, "a FITS file: give a name ending in .fits (or .fit, .fts, .wcs)"),
        ("new_fits", WCS_SUFFIXES[:3], "a FITS file: give a name ending in .fits (.fit, .fts)"),
        ("annotate", (".png",), "a PNG file: give a name ending in .png"),
    )
    for option, suffixes, what in checks:
        value = getattr(args, option)
        flag = f"--{option.replace('_', '-')}"
        if value and not value.lower().endswith(suffixes):
            raise StarnavError(f"{flag} writes {what}, got {value!r}")
        check_parent_dir(flag, value)


def run_batch(args: argparse.Namespace, inputs: list[Path]) -> int:
    """Many files in one process (``starnav.pipeline.image_batch``): a progress bar, one line per
    file (text, or JSON with --json; --jsonl writes them to a file as well), a summary."""
    from tqdm import tqdm

    from starnav.pipeline import image_batch as batch

    skipped: list[Path] = []
    paths = batch.image_paths(inputs, skipped)
    if skipped:
        print(f"starnav solve: {batch.skipped_line(skipped)}", file=sys.stderr)
    outputs = batch.ImageOutputs.make(wcs=args.wcs, new_fits=args.new_fits, annotate=args.annotate)
    jsonl = None
    if args.jsonl:
        check_parent_dir("--jsonl", args.jsonl)
        try:
            jsonl = open(args.jsonl, "w")
        except OSError as exc:
            raise StarnavError(f"cannot write {args.jsonl!r}: {exc.strerror or exc}") from None
    t0 = time.perf_counter()
    with tqdm(total=len(paths), desc="solve", unit="file", file=sys.stderr) as bar:
        results = batch.solve_files(
            paths,
            image_solve_options(args),
            outputs=outputs,
            workers=args.workers,
            dask_address=args.dask,
            track=args.track,
            progress=bar.update,
        )
    summary = batch.summarize(results, time.perf_counter() - t0)
    for r in results:
        if jsonl is not None:
            jsonl.write(to_json(r.record) + "\n")
        if args.json:
            print_json(r.record)
        else:
            print(r.line())
    if jsonl is not None:
        jsonl.close()
    print(summary.line(), file=sys.stderr)
    if summary.errors:
        return EXIT_BAD_INPUT
    return EXIT_OK if summary.solved == summary.files else EXIT_NOT_SOLVED


def _print_text(res: ImageSolveResult) -> None:
    s, cam = res.solution, res.camera
    if s is None:
        print(
            f"not solved: {res.reason} ({len(res.detections.xy)} stars detected, "
            f"{res.total_ms:.1f} ms)"
        )
        return
    print_solution(s)
    coefficients = "".join(f" {k} {getattr(cam, k):.5f}" for k in cam.coefficients)
    print(
        f"  camera: {cam.model}, FOV {cam.fov_deg:.4f}°,{coefficients}; "
        f"{len(res.detections.xy)} stars detected; "
        f"read {res.read_ms:.1f} ms, detect {res.detect_ms:.1f} ms, solve {res.solve_ms:.1f} ms"
    )
