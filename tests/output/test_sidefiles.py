"""solve-field's side files as ``starnav-solve-field`` writes them (``starnav.output
.sidefiles``): solve-field's names, columns and formats, read back with astropy, the rows
consistent with each other and with the WCS, and read by astrometry.net's own tools
(``wcsinfo``, ``wcs-xy2rd``, ``wcs-rd2xy``; Debian's package ships no ``tablist`` or
``listhead``) where they are installed."""

from __future__ import annotations

import shutil
import subprocess
import zipfile
from pathlib import Path

import numpy as np
import pytest
from astropy.io import fits
from astropy.wcs import WCS

from shared_data import REAL, shared_file
from starnav.dropin.solve_field import main as solve_field

pytestmark = pytest.mark.filterwarnings("ignore::astropy.wcs.FITSFixedWarning")

IMAGE = "granasat_pleyades_05sec.jpg"
# solve-field 0.93's columns (Debian's, run on this image: solver/solve-field.c and friends)
AXY = [("X", "E"), ("Y", "E"), ("FLUX", "E"), ("BACKGROUND", "E")]
CORR = [("field_x", "D"), ("field_y", "D"), ("field_ra", "D"), ("field_dec", "D"),
        ("index_x", "D"), ("index_y", "D"), ("index_ra", "D"), ("index_dec", "D"),
        ("index_id", "J"), ("field_id", "J"), ("match_weight", "D"), ("FLUX", "E"),
        ("BACKGROUND", "E")]  # fmt: skip


@pytest.fixture(scope="module")
def solved(tmp_path_factory):
    folder = tmp_path_factory.mktemp("side")
    image = folder / "img.jpg"
    image.write_bytes(shared_file(REAL / IMAGE).read_bytes())
    code = solve_field([str(image), "--no-plots", "--kmz", "%s.kmz", "--keep-xylist",
                        "%s.xyls"])  # fmt: skip
    assert code == 0
    return folder


def _table(path):
    with fits.open(path) as hdul:
        return hdul[0].header, hdul[1].header, hdul[1].columns, np.array(hdul[1].data)


def _columns(columns) -> list[tuple[str, str]]:
    return [(c.name, c.format.lstrip("1")) for c in columns]


def test_default_names_and_columns(solved):
    names = sorted(p.name for p in solved.iterdir())
    assert names == ["img-indx.xyls", "img.axy", "img.corr", "img.jpg", "img.kmz", "img.match",
                     "img.new", "img.rdls", "img.solved", "img.wcs", "img.xyls"]  # fmt: skip
    primary, header, columns, axy = _table(solved / "img.axy")
    assert _columns(columns) == AXY
    assert primary["ANRUN"] is True and primary["IMAGEW"] == 1280 and primary["IMAGEH"] == 960
    assert header["IMAGEW"] == 1280 and len(axy) >= 20
    assert _columns(_table(solved / "img.corr")[2]) == CORR
    assert _columns(_table(solved / "img.rdls")[2]) == [("RA", "D"), ("DEC", "D")]
    assert _columns(_table(solved / "img-indx.xyls")[2]) == [("X", "D"), ("Y", "D")]
    assert _columns(_table(solved / "img.xyls")[2]) == AXY


def test_rows_agree_with_each_other_and_the_wcs(solved):
    wcs = WCS(fits.getheader(solved / "img.wcs"))
    axy = _table(solved / "img.axy")[3]
    rdls = _table(solved / "img.rdls")[3]
    index_xy = _table(solved / "img-indx.xyls")[3]
    corr = _table(solved / "img.corr")[3]
    assert len(corr) >= 20
    # index_id is the row in .rdls / -indx.xyls, field_id the row in .axy
    np.testing.assert_allclose(rdls["RA"][corr["index_id"]], corr["index_ra"])
    np.testing.assert_allclose(index_xy["X"][corr["index_id"]], corr["index_x"])
    np.testing.assert_allclose(axy["X"][corr["field_id"]], corr["field_x"], atol=1e-3)
    # every catalog star listed is inside the image, where the WCS puts it
    xy = wcs.all_world2pix(np.column_stack([rdls["RA"], rdls["DEC"]]), 1)
    np.testing.assert_allclose(xy, np.column_stack([index_xy["X"], index_xy["Y"]]), atol=1e-6)
    assert (xy >= 0.5).all() and (xy[:, 0] <= 1280.5).all() and (xy[:, 1] <= 960.5).all()
    # a matched star and its catalog star: the fit's residuals (TAN-SIP on this lens)
    gap = np.hypot(corr["field_x"] - corr["index_x"], corr["field_y"] - corr["index_y"])
    assert np.sqrt(np.mean(gap**2)) < 0.5
    sky = wcs.all_pix2world(np.column_stack([corr["field_x"], corr["field_y"]]), 1)
    np.testing.assert_allclose(sky[:, 1], corr["field_dec"], atol=1e-9)
    assert ((corr["match_weight"] > 0) & (corr["match_weight"] <= 1)).all()


def test_match_file(solved):
    primary, _, _, match = _table(solved / "img.match")
    assert primary["AN_FILE"] == "MATCH" and len(match) == 1
    row = match[0]
    corr = _table(solved / "img.corr")[3]
    wcs = WCS(fits.getheader(solved / "img.wcs"))
    assert row["NMATCH"] == len(corr) and row["NFIELD"] == len(_table(solved / "img.axy")[3])
    np.testing.assert_allclose(row["CRVAL"], wcs.wcs.crval)
    np.testing.assert_allclose(row["CD"], wcs.pixel_scale_matrix.ravel())
    assert row["WCS_VALID"] and row["PARITY"]  # a JPEG read top row first: "neg"
    assert row["LOGODDS"] > 20 and 10 < row["RADIUS"] < 20
    assert abs(np.linalg.norm(row["CENTERXYZ"]) - 1) < 1e-12


def test_kmz_is_a_ground_overlay(solved):
    with zipfile.ZipFile(solved / "img.kmz") as kmz:
        assert sorted(kmz.namelist()) == ["doc.kml", "image.png"]
        kml = kmz.read("doc.kml").decode()
        assert kmz.read("image.png").startswith(b"\x89PNG")
    assert 'hint="target=sky"' in kml and "<gx:LatLonQuad>" in kml
    coords = kml.split("<coordinates>")[1].split("</coordinates>")[0].split()
    lon_lat = np.array([[float(v) for v in c.split(",")] for c in coords])
    assert len(lon_lat) == 4
    # the Pleiades field: RA ~52° is longitude ~-128° in the sky mode, Dec ~24°
    assert np.all(np.abs(lon_lat[:, 0] + 128) < 25) and np.all(np.abs(lon_lat[:, 1] - 24) < 20)


def _tool(name: str) -> str:
    path = shutil.which(name)
    if path is None:
        debian = name in ("tablist", "listhead")  # qfits tools Debian's package leaves out
        why = (
            "Debian's astrometry.net package does not ship it"
            if debian
            else ("apt-get install astrometry.net")
        )
        pytest.skip(f"astrometry.net's {name} is not installed ({why})")
    return path


def test_read_by_astrometry_net_tools(solved, tmp_path):
    """wcsinfo reads the TAN-SIP WCS; wcs-xy2rd maps the .axy's X, Y and wcs-rd2xy the
    .rdls's RA, DEC through it, to what the .corr and -indx.xyls say."""
    out = subprocess.run([_tool("wcsinfo"), str(solved / "img.wcs")], capture_output=True,
                         text=True, check=True).stdout  # fmt: skip
    info = dict(line.split(" ", 1) for line in out.splitlines() if " " in line)
    wcs = WCS(fits.getheader(solved / "img.wcs"))
    ra, dec = wcs.all_pix2world([[640.5, 480.5]], 1)[0]
    assert float(info["ra_center"]) == pytest.approx(ra, abs=1e-6)
    assert float(info["dec_center"]) == pytest.approx(dec, abs=1e-6)
    subprocess.run([_tool("wcs-xy2rd"), "-w", str(solved / "img.wcs"), "-i",
                    str(solved / "img.axy"), "-o", str(tmp_path / "rd.fits")],
                   check=True, capture_output=True)  # fmt: skip
    rd = _table(tmp_path / "rd.fits")[3]
    corr = _table(solved / "img.corr")[3]
    np.testing.assert_allclose(rd["DEC"][corr["field_id"]], corr["field_dec"], atol=1e-5)
    subprocess.run([_tool("wcs-rd2xy"), "-w", str(solved / "img.wcs"), "-i",
                    str(solved / "img.rdls"), "-o", str(tmp_path / "xy.fits")],
                   check=True, capture_output=True)  # fmt: skip
    xy = _table(tmp_path / "xy.fits")[3]
    index_xy = _table(solved / "img-indx.xyls")[3]
    # astrometry.net's inverse is AP/BP (no iteration): good to 0.01 px over the image
    np.testing.assert_allclose(xy["X"], index_xy["X"], atol=0.02)
    np.testing.assert_allclose(xy["Y"], index_xy["Y"], atol=0.02)


def test_tablist_and_listhead(solved):
    """The tools the brief names: Debian's astrometry.net ships neither (skipped there)."""
    tablist, listhead = _tool("tablist"), _tool("listhead")
    out = subprocess.run([tablist, f"{solved / 'img.corr'}[1]"], capture_output=True,
                         text=True, check=True).stdout  # fmt: skip
    assert "field_x" in out and "index_id" in out
    head = subprocess.run([listhead, str(solved / "img.axy")], capture_output=True, text=True,
                          check=True).stdout  # fmt: skip
    assert "ANRUN" in head


def test_none_and_temp_axy_disable(tmp_path):
    image = tmp_path / "img.jpg"
    image.write_bytes(shared_file(REAL / IMAGE).read_bytes())
    code = solve_field([str(image), "-p", "-B", "none", "-M", "none", "-R", "none", "-U",
                        "none", "--temp-axy", "-N", "none"])  # fmt: skip
    assert code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["img.jpg", "img.solved", "img.wcs"]


@pytest.mark.slow
def test_same_tables_as_debian_solve_field(solved, tmp_path):
    """Debian's solve-field on the same image (its Tycho-2 index files installed): our files
    have its columns and formats (.match: a subset of its MatchObj), and the stars both
    matched sit at the same pixels in both .corr files."""
    solve_field_program = _tool("solve-field")
    if not list(Path("/usr/share/astrometry").glob("index-tycho2-1[5-9]*.fits")):
        pytest.skip("astrometry.net's Tycho-2 index files 15-19 are not installed "
                    "(apt-get install astrometry-data-tycho2-10-19)")  # fmt: skip
    image = tmp_path / "img.jpg"
    image.write_bytes((solved / "img.jpg").read_bytes())
    run = subprocess.run([solve_field_program, str(image), "--no-plots", "--overwrite",
                          "--crpix-center", "--scale-units", "degwidth", "--scale-low", "20",
                          "--scale-high", "35", "--cpulimit", "60", "--new-fits", "none"],
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    if not (tmp_path / "img.solved").exists():
        pytest.skip(f"solve-field did not solve the image here: {run.stdout[-300:]}")
    for name in ("img.axy", "img.corr", "img.rdls", "img-indx.xyls"):
        theirs, ours = _table(tmp_path / name)[2], _table(solved / name)[2]
        assert [c.name for c in ours] == [c.name for c in theirs], name
        # same kinds (float / integer); solve-field writes its .axy in single precision
        assert [c.format[-1] for c in ours] == [c.format[-1] for c in theirs], name
    theirs_match = {c.name for c in _table(tmp_path / "img.match")[2]}
    ours_match = {c.name for c in _table(solved / "img.match")[2]}
    assert ours_match <= theirs_match
    theirs, ours = _table(tmp_path / "img.corr")[3], _table(solved / "img.corr")[3]
    gap = np.hypot(theirs["field_x"][:, None] - ours["field_x"][None],
                   theirs["field_y"][:, None] - ours["field_y"][None])  # fmt: skip
    i, j = np.nonzero(gap < 1.0)
    assert len(i) >= 10
    np.testing.assert_allclose(ours["index_ra"][j], theirs["index_ra"][i], atol=5e-3)
    index_gap = np.hypot(ours["index_x"][j] - theirs["index_x"][i],
                         ours["index_y"][j] - theirs["index_y"][i])  # fmt: skip
    assert np.median(index_gap) < 0.3
