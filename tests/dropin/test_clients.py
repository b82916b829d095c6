"""Each client's exact command line, as its public source writes it, run end to end through
``starnav-solve-field`` / ``starnav-astap`` on a real photograph (the GranaSAT Pleiades
frame, 27° wide): the field must solve, the files the client reads must exist, and the image
centre they give must lie within ``CENTRE_TOL_ARCMIN`` of astrometry.net's
(tests/data/real/reference.json). docs/dropin.md lists the lines and where each came from;
the hints (scale, position) are those the client would compute for this frame.

Inputs are the frame as a FITS image (what N.I.N.A., INDI, CCDciel, Ekos save) or a source
list of its stars in detection order (Siril's and StellarSolver's xylists: ``source_lists``).
"""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
from astropy.io import fits
from astropy.wcs import WCS, FITSFixedWarning

from shared_data import ROOT
from source_lists import (
    PLEIADES,
    REAL_REFERENCE,
    centre_offset_arcmin,
    plain_xylist,
    pleiades_fits,
    pleiades_path,
    pleiades_sources,
    random_xylist,
    siril_xylist,
    stellarsolver_xylist,
)

pytestmark = pytest.mark.slow  # each runs a program as a process: 3-6 s

CENTRE_TOL_ARCMIN = 3.0
REF = REAL_REFERENCE[PLEIADES]
SCALE = REF["scale_arcsec_per_px"]  # 77.7 "/px
HEIGHT_DEG = REF["fov_deg"] * 960 / 1280  # about the image height (ASTAP's -fov)
RA_H, SPD = REF["ra_deg"] / 15.0, REF["dec_deg"] + 90.0


def _env() -> dict:
    env = dict(os.environ)
    src = str(ROOT / "src")
    env["PYTHONPATH"] = os.pathsep.join([src, env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return env


def _run(module: str, argv: list[str], cwd: Path) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", f"starnav.dropin.{module}", *argv]
    return subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, timeout=180,
                          env=_env())  # fmt: skip


def _wcs_centre(path: Path) -> tuple[float, float]:
    """The sky at the image centre through a .wcs file (FITS header, as astropy reads it)."""
    header = fits.getheader(path)
    w, h = 1280, 960
    with warnings.catch_warnings():  # a .wcs is a header of NAXIS 0
        warnings.simplefilter("ignore", FITSFixedWarning)
        wcs = WCS(header)
    ra, dec = wcs.all_pix2world([[(w + 1) / 2.0, (h + 1) / 2.0]], 1)[0]
    return float(ra), float(dec)


def _ini(path: Path) -> dict:
    return dict(line.split("=", 1) for line in path.read_text().splitlines() if "=" in line)


def _solved_lines(out: str) -> tuple[float, float]:
    """solve-field's centre line, as Siril and INDI look for it."""
    assert "Did not solve" not in out, out
    line = next(ln for ln in out.splitlines() if ln.startswith("Field center: (RA,Dec) = ("))
    ra, dec = line.split("(")[2].split(")")[0].split(",")
    return float(ra), float(dec)


def _check_centre(ra: float, dec: float) -> None:
    off = centre_offset_arcmin(ra, dec)
    assert off < CENTRE_TOL_ARCMIN, f"centre {ra:.4f}, {dec:.4f} is {off:.2f}' off"


def _wcsinfo_centre(path: Path) -> tuple[float, float] | None:
    """astrometry.net's wcsinfo reading of a .wcs (what N.I.N.A. and StellarSolver run), None
    when Debian's astrometry.net is not installed."""
    exe = shutil.which("wcsinfo")
    if exe is None:
        return None
    out = subprocess.run([exe, str(path)], capture_output=True, text=True, timeout=30).stdout
    values = dict(line.split(" ", 1) for line in out.splitlines() if " " in line)
    return float(values["ra_center"]), float(values["dec_center"])


def test_siril_xylist(tmp_path):
    """Siril (lock042/siril src/algos/astrometry_solver.c, local_asnet_platesolve): its own
    star list IMG.xyls, the stop file "stop" in its working folder, reads IMG.wcs and the
    "Field center" / "Did not solve" lines; -T when no SIP order is asked."""
    siril_xylist(tmp_path / "IMG.xyls")
    argv = ["-C", "stop", "--temp-axy", "-p", "-O", "-N", "none", "-R", "none", "-M", "none",
            "-B", "none", "-U", "none", "-S", "none", "--crpix-center", "-s", "FLUX",
            "-u", "arcsecperpix", "-L", f"{SCALE * 0.9:.3f}", "-H", f"{SCALE * 1.1:.3f}",
            "-l", "10", "-T", "--ra", f"{REF['ra_deg'] + 1.5:f}", "--dec",
            f"{REF['dec_deg'] - 1.0:f}", "--radius", "10.0", "IMG.xyls"]  # fmt: skip
    done = _run("solve_field", argv, tmp_path)
    assert done.returncode == 0, done.stderr
    _check_centre(*_solved_lines(done.stdout))
    header = fits.getheader(tmp_path / "IMG.wcs")
    assert header["CTYPE1"] == "RA---TAN" and "A_ORDER" not in header  # -T: no SIP
    _check_centre(*_wcs_centre(tmp_path / "IMG.wcs"))
    assert not (tmp_path / "none").exists()  # "none": not written
    assert not (tmp_path / "IMG.new").exists()


def test_xylist_without_brightness_in_detection_order(tmp_path):
    """An xylist of X and Y only, rows in detection order (image2xy's and SExtractor's, and
    what astrometry.net's client.py --upload-xy sends), with the scale as Siril sends it:
    solved without brightness (issue 36.2), the centre and the .wcs as for a sorted list."""
    plain_xylist(tmp_path / "IMG.xyls")
    argv = ["-p", "-O", "--crpix-center", "-u", "arcsecperpix", "-L", f"{SCALE * 0.9:.3f}",
            "-H", f"{SCALE * 1.1:.3f}", "-l", "10", "IMG.xyls"]  # fmt: skip
    done = _run("solve_field", argv, tmp_path)
    assert done.returncode == 0, done.stderr
    _check_centre(*_solved_lines(done.stdout))
    _check_centre(*_wcs_centre(tmp_path / "IMG.wcs"))


def test_siril_issue_line_on_the_image(tmp_path):
    """The line of issue 36 (Siril's, on an image rather than a list: starnav detects)."""
    shutil.copy(pleiades_path(), tmp_path / "IMG.jpg")
    argv = ["-C", "stop", "--temp-axy", "-p", "-O", "-N", "none", "-R", "none", "-M", "none",
            "-B", "none", "-U", "none", "-S", "none", "--crpix-center", "-l", "10",
            "-u", "arcsecperpix", "-L", "60", "-H", "90", "-T", "IMG.jpg"]  # fmt: skip
    done = _run("solve_field", argv, tmp_path)
    assert done.returncode == 0, done.stderr
    _check_centre(*_solved_lines(done.stdout))
    _check_centre(*_wcs_centre(tmp_path / "IMG.wcs"))


def test_siril_cancel_file_stops_the_solve(tmp_path):
    """-C FILE: a stop file there from the start ends the solve at once (solve-field prints
    "Did not solve", exit 0, no .wcs)."""
    siril_xylist(tmp_path / "IMG.xyls")
    (tmp_path / "stop").touch()
    done = _run("solve_field", ["-C", "stop", "-p", "-O", "-S", "none", "IMG.xyls"], tmp_path)
    assert done.returncode == 0, done.stderr
    assert "Did not solve" in done.stdout and "cancel file" in done.stdout
    assert not (tmp_path / "IMG.wcs").exists()


def test_cancel_file_created_while_solving(tmp_path):
    """-C FILE created during a solve (points at random, which run to the 30 s budget
    unsolved) stops it within a second or two, as Siril's cancel button does."""
    random_xylist(tmp_path / "IMG.xyls")
    cmd = [sys.executable, "-m", "starnav.dropin.solve_field", "-C", "stop", "-p", "-O",
           "-l", "30", "IMG.xyls"]  # fmt: skip
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=_env())  # fmt: skip
    try:
        for line in proc.stdout:
            if line.startswith("Solving"):
                break
        time.sleep(1.0)
        (tmp_path / "stop").touch()
        t0 = time.monotonic()
        out = proc.stdout.read()
        assert proc.wait(timeout=30) == 0, proc.stderr.read()
        assert time.monotonic() - t0 < 5.0
    finally:
        proc.kill()
    assert "cancel file" in out and "Did not solve" in out
    assert not (tmp_path / "IMG.wcs").exists()


def test_stellarsolver_external_sextractor_list(tmp_path):
    """KStars / StellarSolver's external solver with its own star extraction
    (rlancaste/stellarsolver stellarsolver/externalextractorsolver.cpp, getSolverArgsList,
    runExternalSolver): X_IMAGE, Y_IMAGE, MAG_AUTO sorted by --sort-column; it reads the
    -W file with wcsinfo and checks --solved."""
    stellarsolver_xylist(tmp_path / "ss.xyls")
    *_, width, height = pleiades_sources()
    base = tmp_path / "ss"
    argv = ["-O", "--no-plots", "--no-verify", "--crpix-center", "--match", "none",
            "--corr", "none", "--new-fits", "none", "--rdls", "none", "--resort",
            "--odds-to-solve", "1e+09", "--odds-to-tune-up", "1e+06",
            "-L", f"{SCALE * 0.8:g}", "-H", f"{SCALE * 1.2:g}", "-u", "app",
            "--width", str(width), "--height", str(height),
            "--x-column", "X_IMAGE", "--y-column", "Y_IMAGE", "--sort-column", "MAG_AUTO",
            "--sort-ascending", "--no-remove-lines", "--uniformize", "0", "-vv",
            "--backend-config", f"{base}.cfg", "--cancel", f"{base}.cancel",
            "--solved", f"{base}.solved", "-W", f"{base}.wcs", f"{base}.xyls"]  # fmt: skip
    done = _run("solve_field", argv, tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "ss.solved").exists()
    _check_centre(*_wcs_centre(tmp_path / "ss.wcs"))
    from_wcsinfo = _wcsinfo_centre(tmp_path / "ss.wcs")
    if from_wcsinfo is not None:
        _check_centre(*from_wcsinfo)
    # the options it tunes astrometry.net's engine with are named once, not refused
    assert "ignored: --uniformize 0" in done.stderr
    assert done.stderr.count("ignored: --verbose") == 1


def test_stellarsolver_builtin_extraction_image(tmp_path):
    """Ekos / StellarSolver's external local astrometry.net with astrometry.net's own
    extraction (EXTRACTOR_BUILTIN: the image as FITS, --fits-image, --keep-xylist)."""
    image = pleiades_fits(tmp_path / "ekos.fits")
    base = tmp_path / "ekos"
    argv = ["-O", "--no-plots", "--no-verify", "--crpix-center", "--match", "none",
            "--corr", "none", "--new-fits", "none", "--rdls", "none", "--resort",
            "--downsample", "2", "--odds-to-solve", "1e+09", "--odds-to-tune-up", "1e+06",
            "-3", f"{REF['ra_deg'] + 2:g}", "-4", f"{REF['dec_deg'] - 1:g}", "-5", "15",
            "--no-remove-lines", "--uniformize", "0", "--fits-image",
            "--backend-config", f"{base}.cfg", "--cancel", f"{base}.cancel",
            "--solved", f"{base}.solved", "--axy", f"{base}.axy", "-W", f"{base}.wcs",
            "--keep-xylist", f"{base}.xyls", str(image)]  # fmt: skip
    done = _run("solve_field", argv, tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "ekos.solved").exists()
    _check_centre(*_wcs_centre(tmp_path / "ekos.wcs"))


def test_indi_astrometry_defaults(tmp_path):
    """INDI's indi_astrometry (indilib/indi drivers/auxiliary/astrometrydriver.cpp): its
    default options, then -W /tmp/solution.wcs /tmp/ccdsolver.fits (here in a test folder);
    it reads the printed lines."""
    image = pleiades_fits(tmp_path / "ccdsolver.fits")
    argv = ["--no-verify", "--no-plots", "--resort", "--downsample", "2", "-O",
            "-W", str(tmp_path / "solution.wcs"), str(image)]  # fmt: skip
    done = _run("solve_field", argv, tmp_path)
    assert done.returncode == 0, done.stderr
    _check_centre(*_solved_lines(done.stdout))
    assert "Field rotation angle: up is" in done.stdout and "pixel scale" in done.stdout
    _check_centre(*_wcs_centre(tmp_path / "solution.wcs"))


def test_nina_local_astrometry(tmp_path):
    """N.I.N.A.'s local astrometry.net (isbeorn/nina NINA.Platesolving/Solvers/
    LocalPlateSolver.cs): "-center" as it writes it (getopt reads "-c enter", a code
    tolerance: ignored); it reads BASE.wcs with wcsinfo."""
    image = pleiades_fits(tmp_path / "nina.fits")
    argv = ["--overwrite", "--index-xyls", "none", "--corr", "none", "--rdls", "none",
            "--match", "none", "--new-fits", "none", "-center", "--objs", "500",
            "--no-plots", "--resort", "--downsample", "2", "--scale-units", "arcsecperpix",
            "-L", f"{SCALE * 0.9:.2f}", "-H", f"{SCALE * 1.1:.2f}",
            "--ra", f"{REF['ra_deg']:.2f}", "--dec", f"{REF['dec_deg']:.2f}",
            "--radius", "30.00", str(image)]  # fmt: skip
    done = _run("solve_field", argv, tmp_path)
    assert done.returncode == 0, done.stderr
    assert "ignored: --code-tolerance enter" in done.stderr
    _check_centre(*_wcs_centre(tmp_path / "nina.wcs"))
    from_wcsinfo = _wcsinfo_centre(tmp_path / "nina.wcs")
    if from_wcsinfo is not None:
        _check_centre(*from_wcsinfo)


def test_ccdciel_solve_field(tmp_path):
    """CCDciel (pchev/ccdciel src/cu_astrometry_engine.pas, TAstrometry_engine.Solve, the
    non-Windows branch): it reads FILE.wcs and FILE.solved."""
    image = pleiades_fits(tmp_path / "capture.fits")
    argv = ["--overwrite", "--scale-low", f"{SCALE * 0.8:g}", "--scale-high",
            f"{SCALE * 1.2:g}", "--scale-units", "arcsecperpix", "--ra",
            f"{REF['ra_deg'] - 1:g}", "--dec", f"{REF['dec_deg'] + 1:g}", "--radius", "10",
            "--objs", "150", "--downsample", "2", "--no-plots", str(image)]  # fmt: skip
    done = _run("solve_field", argv, tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "capture.solved").exists()
    _check_centre(*_wcs_centre(tmp_path / "capture.wcs"))


def _astap_centre(ini: dict) -> tuple[float, float]:
    assert ini["PLTSOLVD"] == "T", ini
    return float(ini["CRVAL1"]), float(ini["CRVAL2"])


@pytest.mark.parametrize("hinted", [True, False], ids=["position", "blind"])
def test_nina_astap(tmp_path, hinted):
    """N.I.N.A.'s ASTAP (isbeorn/nina NINA.Platesolving/Solvers/ASTAPSolver.cs,
    GetArguments): -f -fov (height) -z -s, then -r -ra (hours) -spd, or -r 180; it reads
    FILE.ini (PLTSOLVD, CRVAL, CRPIX, CD, WARNING, ERROR)."""
    image = pleiades_fits(tmp_path / "nina.fits")
    argv = ["-f", str(image), "-fov", f"{round(HEIGHT_DEG, 6)}", "-z", "0", "-s", "500"]
    if hinted:
        argv += ["-r", "30", "-ra", f"{round(RA_H + 0.1, 6)}", "-spd", f"{round(SPD - 1, 6)}"]
    else:
        argv += ["-r", "180"]
    done = _run("astap", argv, tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    _check_centre(*_astap_centre(_ini(tmp_path / "nina.ini")))
    assert (tmp_path / "nina.wcs").exists()


def test_ccdciel_astap(tmp_path):
    """CCDciel's ASTAP (pchev/ccdciel src/cu_astrometry_engine.pas, ResolverAstap): -log -z
    -r 180 -f FILE (no -fov: ASTAP takes the scale from the header); it reads the exit code,
    FILE.wcs and FILE.log."""
    image = pleiades_fits(tmp_path / "capture.fits")
    done = _run("astap", ["-log", "-z", "0", "-r", "180", "-f", str(image)], tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "capture.log").exists()
    _check_centre(*_wcs_centre_text(tmp_path / "capture.wcs"))


def _wcs_centre_text(path: Path) -> tuple[float, float]:
    """ASTAP's text .wcs (one 80-character card a line) read as a header."""
    header = fits.Header.fromstring(path.read_text(), sep="\n")
    return float(header["CRVAL1"]), float(header["CRVAL2"])


def test_stellarsolver_astap(tmp_path):
    """StellarSolver's external ASTAP (externalextractorsolver.cpp, runExternalASTAPSolver):
    -o BASE.ini -speed auto -f FILE -wcs -z 0 -fov H -ra -spd -r -log; it reads BASE.ini and
    the FITS-header BASE.wcs."""
    image = pleiades_fits(tmp_path / "ss.fits")
    argv = ["-o", str(tmp_path / "ss.ini"), "-speed", "auto", "-f", str(image), "-wcs",
            "-z", "0", "-fov", f"{HEIGHT_DEG:g}", "-ra", f"{RA_H:g}", "-spd", f"{SPD:g}",
            "-r", "15", "-log"]  # fmt: skip
    done = _run("astap", argv, tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    _check_centre(*_astap_centre(_ini(tmp_path / "ss.ini")))
    _check_centre(*_wcs_centre(tmp_path / "ss.wcs"))
    assert math.isfinite(fits.getheader(tmp_path / "ss.wcs")["CD1_1"])


@pytest.mark.skipif(shutil.which("source-extractor") is None,
                    reason="SExtractor (Debian's source-extractor) is not installed")  # fmt: skip
def test_use_source_extractor(tmp_path):
    """--use-source-extractor: the stars SExtractor finds in the JPEG (handed over as FITS),
    sorted by MAG_AUTO, as solve-field runs it."""
    shutil.copy(pleiades_path(), tmp_path / "p.jpg")
    done = _run("solve_field", ["-O", "-p", "--use-source-extractor", "p.jpg"], tmp_path)
    assert done.returncode == 0, done.stderr
    _check_centre(*_solved_lines(done.stdout))
    _check_centre(*_wcs_centre(tmp_path / "p.wcs"))


def test_source_extractor_that_cannot_run(tmp_path):
    shutil.copy(pleiades_path(), tmp_path / "p.jpg")
    argv = ["-O", "--source-extractor-path", str(tmp_path / "no-such-program"), "p.jpg"]
    done = _run("solve_field", argv, tmp_path)
    assert done.returncode == 2 and "cannot run SExtractor" in done.stderr
    assert done.stderr.count("\n") == 1 and "Traceback" not in done.stderr


def test_astap_analyse(tmp_path):
    """ASTAP's -analyse: HFD_MEDIAN= and STARS= on stdout, exit 0, nothing solved; the
    brighter the floor, the fewer the stars."""
    image = pleiades_fits(tmp_path / "a.fits")
    counts = []
    for floor in ("0", "10"):
        done = _run("astap", ["-f", str(image), "-analyse", floor], tmp_path)
        assert done.returncode == 0, done.stderr
        values = _ini_lines(done.stdout)
        assert 1.0 < float(values["HFD_MEDIAN"]) < 10.0
        counts.append(int(values["STARS"]))
    assert 0 < counts[0] < counts[1]  # 0 means ASTAP's default floor, 30
    assert not (tmp_path / "a.ini").exists()
    missing = _run("astap", ["-f", str(tmp_path / "none.fits"), "-analyse", "0"], tmp_path)
    assert missing.returncode == 16


def _ini_lines(text: str) -> dict:
    return dict(line.split("=", 1) for line in text.splitlines() if "=" in line)
