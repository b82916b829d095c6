"""starnav.detect: reading image files, and detecting + centroiding stars on rendered images
against their true positions."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from PIL import Image
from scipy.spatial import cKDTree
from scipy.stats import spearmanr

from starnav.catalog import load_catalog
from starnav.detect.read import read_image
from starnav.detect.stars import Detections, detect_stars, without_glare, without_trails
from starnav.errors import ImageError
from starnav.geometry import attitude_from_radec_roll
from starnav.simulate.render import (
    PRESETS,
    RenderSettings,
    flux_e_for_snr,
    render_frame,
    render_stars,
    star_electrons,
    star_snr,
    write_image,
)


def _grid(n_side: int, size: int, rng: np.random.Generator) -> np.ndarray:
    """n_side² star positions on a regular grid, each moved by a random sub-pixel offset."""
    g = (np.arange(n_side) + 0.5) * size / n_side
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    return xy + rng.uniform(-0.5, 0.5, xy.shape)


def _match(found: np.ndarray, truth: np.ndarray, radius: float = 1.5):
    """(index into truth or -1 per detection, offsets of the matched ones)."""
    dist, nearest = cKDTree(truth).query(found)
    ok = dist < radius
    return np.where(ok, nearest, -1), found[ok] - truth[nearest[ok]]


# ----------------------------------------------------------------------------------------------
# centroids


@pytest.mark.parametrize(("sigma", "per_axis_max"), [(0.6, 0.03), (1.0, 0.04), (1.5, 0.05)])
def test_centroid_accuracy_at_snr_50(sigma, per_axis_max):
    """400 stars at SNR 50 (render.star_snr): rms error per axis <= 0.05 px (the Cramér-Rao
    bound is sqrt(2) sigma / SNR: 0.028 px at sigma 1, 0.042 px at sigma 1.5)."""
    rng = np.random.default_rng(11)
    settings = RenderSettings(psf_sigma_px=sigma)
    xy = _grid(20, 512, rng)
    image = render_stars(
        xy, np.full(len(xy), flux_e_for_snr(50.0, settings)), 512, 512, settings, rng
    )
    found = detect_stars(image)
    which, err = _match(found.xy, xy)
    assert len(found) == 400 and (which >= 0).all()
    assert len(np.unique(which)) == 400
    per_axis = np.sqrt(np.mean(err**2))
    assert per_axis <= per_axis_max
    assert np.abs(err.mean(axis=0)).max() < 0.01  # no offset: the +0.5 convention holds
    if sigma <= 1.0:
        assert np.sqrt(np.mean((err**2).sum(axis=1))) <= 0.05  # radial rms too
    assert found.psf_sigma_px == pytest.approx(np.hypot(sigma, 0.3), abs=0.25)


def test_single_star_lands_on_our_convention():
    settings = RenderSettings(seed=2)
    image = render_stars(np.array([[10.5, 20.5]]), np.array([2e5]), 40, 40, settings)
    found = detect_stars(image)
    assert len(found) == 1
    assert found.xy[0] == pytest.approx([10.5, 20.5], abs=0.03)
    assert (found.width, found.height) == (40, 40)
    assert found.background == pytest.approx(50.0, abs=2.0)
    assert found.background_rms == pytest.approx(np.sqrt(75.0), rel=0.15)


def test_faint_stars_and_no_false_detections_in_noise():
    settings = RenderSettings()
    noise = render_stars(np.zeros((0, 2)), np.zeros(0), 512, 512, settings, rng=5)
    assert len(detect_stars(noise)) == 0
    rng = np.random.default_rng(6)
    xy = _grid(15, 512, rng)
    image = render_stars(
        xy, np.full(len(xy), flux_e_for_snr(10.0, settings)), 512, 512, settings, rng
    )
    found = detect_stars(image)
    which, err = _match(found.xy, xy)
    assert (which >= 0).all() and len(found) >= 0.97 * len(xy)  # SNR 10: essentially all found
    assert np.sqrt(np.mean(err**2)) < 0.2


# ----------------------------------------------------------------------------------------------
# whole frames


def test_render_detect_round_trip_on_the_reference_camera():
    catalog = load_catalog(None, mag_limit=7.0)
    camera, settings = PRESETS["seed-1024"]
    R = attitude_from_radec_roll(83.0, -5.0, 20.0)  # Orion: Hp -0.1 .. 7 in view
    frame = render_frame(catalog, camera, R, dataclasses.replace(settings, seed=12, hot_pixels=20))
    found = detect_stars(frame.image)
    which, _ = _match(found.xy, frame.xy, radius=1.0)
    # stars closer than ~4 px are one star to a star tracker (../shared/docs/domain.md): drop them
    separation = cKDTree(frame.xy).query(frame.xy, k=2)[0][:, 1]
    bright = (frame.mag <= 6.5) & (separation > 5.0)
    assert bright.sum() > 100
    assert np.isin(np.flatnonzero(bright), which).all()
    assert (which >= 0).mean() >= 0.97  # almost nothing that is not a catalog star
    assert found.n_hot >= 18
    # brightest first: detection order follows magnitude order
    matched = which >= 0
    rank = spearmanr(np.arange(matched.sum()), frame.mag[which[matched]]).statistic
    assert rank > 0.9
    top = which[:10]
    assert (top >= 0).all() and np.median(top) < 12
    assert np.all(np.diff(found.snr[~found.saturated]) <= 0)  # the documented order
    # isolated stars at SNR >= 50: centroid rms per axis <= 0.05 px
    # (stars cut by the image edge are pulled inwards: left out too)
    away = (frame.xy > 3.0).all(axis=1) & (frame.xy < np.array([1021.0, 1021.0])).all(axis=1)
    strong = bright & away & (star_snr(frame.flux_e, settings) >= 50.0)
    assert strong.sum() >= 20
    nearest = cKDTree(found.xy).query(frame.xy[strong])[1]
    assert np.sqrt(np.mean((found.xy[nearest] - frame.xy[strong]) ** 2)) <= 0.05


def test_max_stars_keeps_the_brightest():
    rng = np.random.default_rng(13)
    xy = _grid(10, 256, rng)
    flux = rng.uniform(2e3, 5e4, len(xy))
    image = render_stars(xy, flux, 256, 256, RenderSettings(), rng)
    every = detect_stars(image)
    some = detect_stars(image, max_stars=7)
    assert len(every) == 100 and len(some) == 7
    assert np.array_equal(some.xy, every.xy[:7])
    which, _ = _match(some.xy, xy)
    assert set(which) == set(np.argsort(-flux)[:7])


def test_hot_pixels_rejected():
    rng = np.random.default_rng(14)
    xy = _grid(8, 256, rng)
    settings = RenderSettings(hot_pixels=40, hot_pixel_adu=2000.0, seed=15)
    frame_settings = dataclasses.replace(settings, psf_sigma_px=0.7)
    image = render_stars(xy, np.full(len(xy), 2e4), 256, 256, frame_settings, rng=16)
    found = detect_stars(image)
    which, _ = _match(found.xy, xy)
    assert (which >= 0).all() and len(found) == 64  # every star, no hot pixel
    assert 35 <= found.n_hot <= 40  # a few may sit on a star
    kept = detect_stars(image, reject_hot_pixels=False)
    assert len(kept) + kept.n_rejected >= 64 + 30 and kept.n_hot == 0


def test_saturated_stars_kept_flagged_and_first():
    settings = RenderSettings(seed=17)
    xy = np.array([[40.3, 40.6], [120.7, 60.2], [80.5, 110.5], [30.2, 100.9]])
    flux = np.array([3e6, 2e4, 1e7, 5e3])  # two of them saturate
    image = render_stars(xy, flux, 160, 140, settings)
    assert (image == 65535).sum() > 10
    found = detect_stars(image)
    assert len(found) == 4 and found.n_saturated == 2
    assert found.saturated.tolist() == [True, True, False, False]
    which, err = _match(found.xy, xy)
    assert which.tolist() == [2, 0, 1, 3]
    assert np.abs(err[:2]).max() < 0.15  # a symmetric saturated star still centroids well
    # a float image (e.g. from read_image) infers saturation from the flat top
    assert detect_stars(image.astype(np.float32)).saturated.tolist() == [True, True, False, False]
    dropped = detect_stars(image, keep_saturated=False)
    assert len(dropped) == 2 and dropped.n_saturated == 2 and not dropped.saturated.any()
    # an explicit level: nothing reaches it
    assert detect_stars(image, saturation=70000).n_saturated == 0


@pytest.mark.parametrize(
    "image",
    [
        np.zeros((64, 64)),
        np.full((64, 64), 1000, dtype=np.uint16),
        np.full((64, 64), np.nan),
        np.zeros((64, 64), dtype=bool),
    ],
    ids=["zeros", "constant", "all-nan", "bool"],
)
def test_blank_images_give_no_stars(image):
    found = detect_stars(image)
    assert len(found) == 0 and found.xy.shape == (0, 2)


def test_nan_pixels_masked_and_byte_order_and_dtypes():
    rng = np.random.default_rng(18)
    xy = _grid(5, 128, rng)
    image = render_stars(xy, np.full(len(xy), 3e4), 128, 128, RenderSettings(), rng)
    reference = detect_stars(image)
    assert len(reference) == 25
    for variant in (image.astype(">u2"), image.astype(np.int32), image.astype(">f8"), image.T.T):
        found = detect_stars(variant)
        assert np.allclose(found.xy, reference.xy, atol=1e-4)
    holed = image.astype(np.float32)
    holed[:20, :] = np.nan  # a dead band across the top
    holed[60, 60] = np.inf
    found = detect_stars(holed)
    which, _ = _match(found.xy, xy)
    assert (which >= 0).all() and np.isfinite(found.xy).all()
    assert len(found) == (xy[:, 1] > 22).sum()


def test_noise_free_image():
    xy = np.array([[20.3, 30.8], [50.5, 10.2]])
    image = star_electrons(xy, np.array([1000.0, 500.0]), 64, 48, 1.0)
    found = detect_stars(image)
    which, err = _match(found.xy, xy)
    assert which.tolist() == [0, 1] and np.abs(err).max() < 0.01


@pytest.mark.parametrize(
    ("image", "kwargs", "match"),
    [
        (np.zeros(10), {}, "2-D"),
        (np.zeros((0, 5)), {}, "2-D"),
        (np.zeros((2, 50)), {}, "too small"),
        (np.zeros((8, 8), dtype="U1"), {}, "numbers"),
        (np.zeros((8, 8)), {"threshold_sigma": 0}, "threshold_sigma"),
        (np.zeros((8, 8)), {"max_stars": 0}, "max_stars"),
        (np.zeros((8, 8)), {"psf_sigma_px": 100.0}, "psf_sigma_px"),
        (np.zeros((8, 8)), {"min_area_px": 1.5}, "min_area_px"),
    ],
)
def test_bad_input(image, kwargs, match):
    with pytest.raises(ImageError, match=match):
        detect_stars(image, **kwargs)


# ----------------------------------------------------------------------------------------------
# reading files


@pytest.fixture(scope="module")
def picture():
    """A 16-bit, asymmetric test picture: a gradient and a bright block near the top left."""
    rows, cols = np.mgrid[0:30, 0:40]
    image = (100 * rows + 7 * cols + 3).astype(np.uint16)
    image[2:5, 3:7] = 60000
    return image


@pytest.mark.parametrize("suffix", [".png", ".tif", ".tiff", ".fits", ".fit"])
def test_write_read_round_trip_16_bit(tmp_path, picture, suffix):
    path = tmp_path / f"picture{suffix}"
    write_image(path, picture)
    back = read_image(path)
    assert back.dtype == np.float32 and back.flags.c_contiguous and back.dtype.isnative
    assert np.array_equal(back, picture.astype(np.float32))  # row 0 stays the top


@pytest.mark.parametrize("suffix", [".png", ".tif", ".fits"])
def test_write_read_round_trip_8_bit_and_float(tmp_path, picture, suffix):
    small = (picture // 256).astype(np.uint8)
    write_image(tmp_path / f"a{suffix}", small)
    assert np.array_equal(read_image(tmp_path / f"a{suffix}"), small.astype(np.float32))
    if suffix != ".png":
        values = picture.astype(np.float32) / 7.0
        write_image(tmp_path / f"b{suffix}", values)
        assert np.array_equal(read_image(tmp_path / f"b{suffix}"), values)


def test_rendered_frame_survives_a_file(tmp_path):
    camera, settings = PRESETS["seed-512"]
    catalog = load_catalog(None, mag_limit=6.0)
    frame = render_frame(catalog, camera, attitude_from_radec_roll(83.0, -5.0, 0.0), settings)
    write_image(tmp_path / "f.png", frame.image)
    direct = detect_stars(frame.image)
    from_file = detect_stars(read_image(tmp_path / "f.png"))
    assert len(direct) > 10
    assert np.allclose(from_file.xy, direct.xy) and np.allclose(from_file.flux, direct.flux)


def test_fits_variants(tmp_path, picture):
    from astropy.io import fits

    # image in an extension after an empty primary, big-endian float, BSCALE/BZERO ints
    path = tmp_path / "ext.fits"
    hdus = [fits.PrimaryHDU(), fits.ImageHDU(picture.astype(">f4"))]
    fits.HDUList(hdus).writeto(path)
    assert np.array_equal(read_image(path), picture.astype(np.float32))
    scaled = fits.PrimaryHDU((picture // 2).astype(np.int16))
    scaled.header["BSCALE"] = 2.0
    scaled.header["BZERO"] = 10.0
    scaled.writeto(tmp_path / "scaled.fits")
    assert np.allclose(read_image(tmp_path / "scaled.fits"), (picture // 2) * 2.0 + 10.0)
    # a (1, H, W) cube is a 2-D image; a 3-plane cube is colour
    fits.PrimaryHDU(picture[None]).writeto(tmp_path / "cube1.fits")
    assert read_image(tmp_path / "cube1.fits").shape == (30, 40)
    rgb = np.stack([picture, picture // 2, picture // 4]).astype(np.float32)
    fits.PrimaryHDU(rgb).writeto(tmp_path / "rgb.fits")
    expected = 0.2126 * rgb[0] + 0.7152 * rgb[1] + 0.0722 * rgb[2]
    assert np.allclose(read_image(tmp_path / "rgb.fits"), expected, rtol=1e-6)
    # gzip-compressed
    write_image(tmp_path / "plain.fits", picture)
    import gzip

    (tmp_path / "z.fits.gz").write_bytes(gzip.compress((tmp_path / "plain.fits").read_bytes()))
    assert np.array_equal(read_image(tmp_path / "z.fits.gz"), picture.astype(np.float32))


def test_colour_pillow_formats(tmp_path):
    rgb = np.zeros((6, 8, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 200, 100, 50
    rgb[1, 2] = (10, 20, 30)
    expected = 0.2126 * 200 + 0.7152 * 100 + 0.0722 * 50
    Image.fromarray(rgb).save(tmp_path / "c.png")
    Image.fromarray(np.dstack([rgb, np.full((6, 8), 128, np.uint8)])).save(tmp_path / "a.png")
    for name in ("c.png", "a.png"):
        lum = read_image(tmp_path / name)
        assert lum.shape == (6, 8)
        assert lum[0, 0] == pytest.approx(expected, rel=1e-6)
        assert lum[1, 2] == pytest.approx(0.2126 * 10 + 0.7152 * 20 + 0.0722 * 30, rel=1e-6)
    Image.fromarray(rgb).convert("P").save(tmp_path / "p.png")
    assert read_image(tmp_path / "p.png")[0, 0] == pytest.approx(expected, abs=3.0)
    flat = np.zeros_like(rgb)
    flat[...] = (200, 100, 50)
    Image.fromarray(flat).save(tmp_path / "c.jpg", quality=95)
    assert np.allclose(read_image(tmp_path / "c.jpg"), expected, atol=2.0)
    grey = np.tile(np.arange(0, 240, 30, dtype=np.uint8), (6, 1))
    Image.fromarray(grey).save(tmp_path / "g.jpg", quality=95)
    assert np.allclose(read_image(tmp_path / "g.jpg"), grey, atol=4.0)


def test_exif_orientation_applied(tmp_path, picture):
    small = (picture // 256).astype(np.uint8)
    exif = Image.Exif()
    exif[0x0112] = 6  # "rotate 90° clockwise to display"
    Image.fromarray(small).save(tmp_path / "o.png", exif=exif)
    shown = read_image(tmp_path / "o.png")
    assert shown.shape == (40, 30)
    assert np.array_equal(shown, np.rot90(small, k=-1).astype(np.float32))


@pytest.mark.filterwarnings("ignore:Truncated File Read")
def test_16_bit_colour_tiff_keeps_16_bits(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    rgb = np.zeros((5, 7, 3), np.uint16)
    rgb[...] = (1000, 40000, 65535)
    rgb[2, 3] = (3, 4, 5)  # Pillow alone would read this pixel as 0
    tifffile.imwrite(tmp_path / "rgb16.tif", rgb, photometric="rgb", compression="zlib")
    lum = read_image(tmp_path / "rgb16.tif")
    assert lum[2, 3] == pytest.approx(0.2126 * 3 + 0.7152 * 4 + 0.0722 * 5, rel=1e-6)
    assert lum[0, 0] == pytest.approx(0.2126 * 1000 + 0.7152 * 40000 + 0.0722 * 65535, rel=1e-6)
    data = (tmp_path / "rgb16.tif").read_bytes()
    (tmp_path / "cut.tif").write_bytes(data[: len(data) - 60])
    with pytest.raises(ImageError, match=r"^cannot read TIFF file '.*cut\.tif': ") as info:
        read_image(tmp_path / "cut.tif")
    assert "\n" not in str(info.value) and str(info.value).count("cannot read") == 1


def test_16_bit_colour_png_keeps_16_bits(tmp_path):
    png = pytest.importorskip("png")
    rgb = np.zeros((5, 7, 3), np.uint16)
    rgb[...] = (1000, 40000, 65535)
    rgb[2, 3] = (3, 4, 5)
    with open(tmp_path / "rgb16.png", "wb") as fh:
        png.Writer(7, 5, greyscale=False, bitdepth=16).write(fh, rgb.reshape(5, -1))
    lum = read_image(tmp_path / "rgb16.png")
    assert lum.shape == (5, 7)
    assert lum[2, 3] == pytest.approx(0.2126 * 3 + 0.7152 * 4 + 0.0722 * 5, rel=1e-6)


@pytest.mark.parametrize(
    ("name", "content", "match"),
    [
        ("garbage.png", b"\x89PNG not really an image" * 10, "cannot read"),
        ("random.jpg", bytes(range(256)) * 4, "cannot read"),
        ("empty.png", b"", "empty"),
        ("empty.fits", b"", "empty"),
        ("text.fits", b"hello world\n" * 300, "not a FITS file"),
        ("bad.fits", b"SIMPLE  =                    T" + b" " * 50 + b"garbage" * 100, "FITS"),
    ],
)
def test_bad_files(tmp_path, name, content, match):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(ImageError, match=match) as info:
        read_image(path)
    message = str(info.value)
    assert "\n" not in message and name in message


def test_truncated_and_missing_files(tmp_path, picture):
    write_image(tmp_path / "whole.png", picture)
    data = (tmp_path / "whole.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[: len(data) // 2])
    for path, match in [
        (tmp_path / "cut.png", "cannot read"),
        (tmp_path / "nope.png", "does not exist"),
        (tmp_path, "not a file"),
    ]:
        with pytest.raises(ImageError, match=match) as info:
            read_image(path)
        assert "\n" not in str(info.value)


def test_fits_without_a_usable_image(tmp_path):
    from astropy.io import fits

    fits.PrimaryHDU(np.arange(10.0)).writeto(tmp_path / "line.fits")
    fits.PrimaryHDU(np.full((4, 4), np.nan, np.float32)).writeto(tmp_path / "nan.fits")
    fits.PrimaryHDU().writeto(tmp_path / "header.fits")
    table = fits.BinTableHDU.from_columns([fits.Column(name="a", format="E", array=np.ones(3))])
    fits.HDUList([fits.PrimaryHDU(), table]).writeto(tmp_path / "table.fits")
    fits.PrimaryHDU(np.zeros((2, 3, 4, 5))).writeto(tmp_path / "4d.fits")
    fits.PrimaryHDU(np.zeros((0, 5), np.float32)).writeto(tmp_path / "zero.fits")
    for name, match in [
        ("line.fits", r"no 2-D image .*\(10,\)"),
        ("nan.fits", "no finite pixel"),
        ("header.fits", "no image data"),
        ("table.fits", "no image data"),
        ("4d.fits", r"no 2-D image .*\(2, 3, 4, 5\)"),
        ("zero.fits", r"empty image \(shape \(0, 5\)\)"),
    ]:
        with pytest.raises(ImageError, match=match):
            read_image(tmp_path / name)


@pytest.mark.parametrize(
    ("height", "width", "step"), [(1024, 1024, 4), (960, 1280, 4), (101, 77, 3)]
)
def test_background_map_subtraction_matches_the_full_size_map(height, width, step):
    from starnav.detect.background import subtract_map as _subtract

    rng = np.random.default_rng(0)
    data = rng.normal(size=(height, width)).astype(np.float32)
    back = rng.normal(size=(-(-height // step), -(-width // step))).astype(np.float32)
    full = np.repeat(np.repeat(back, step, axis=0), step, axis=1)[:height, :width]
    expected = data - full
    _subtract(data, back, step)
    assert np.array_equal(data, expected)


# ----------------------------------------------------------------------------------------------
# real skies: foreground, glow, clouds, moonlight, trails, hot pixels, JPEG (synthetic scenes
# whose every star is known; each test fails with the detection of before these rules)

SIZE = 512
READ_NOISE_E = 5.0


def _stars(rng: np.random.Generator, n: int, clear: np.ndarray | None = None, margin: float = 8.0):
    """n star positions (px, our convention) away from the image edge, in ``clear`` pixels
    (True: sky seen) and ``margin`` px from any that are not, with log-uniform fluxes (e)."""
    from scipy import ndimage

    far = np.ones((SIZE, SIZE), bool) if clear is None else clear
    if clear is not None:
        far = ndimage.distance_transform_edt(clear) > margin
    xy = []
    while len(xy) < n:
        x, y = rng.uniform(6, SIZE - 6, 2)
        if far[int(y), int(x)] and all(np.hypot(x - a, y - b) > 12 for a, b in xy):
            xy.append((x, y))
    return np.array(xy), np.exp(rng.uniform(np.log(600.0), np.log(6e4), n))


def _optics(electrons: np.ndarray, psf_sigma_px: float) -> np.ndarray:
    """The scene as the lens images it: blurred by the PSF like the stars."""
    from scipy import ndimage

    return ndimage.gaussian_filter(electrons, psf_sigma_px)


def _exposed(electrons: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Photon and read noise on an image of electrons, 16-bit ADU (gain 1)."""
    image = rng.poisson(np.clip(electrons, 0, None)) + rng.normal(0, READ_NOISE_E, electrons.shape)
    return np.clip(np.rint(image), 0, 65535).astype(np.uint16)


def _found(found, xy: np.ndarray, radius: float = 1.5) -> np.ndarray:
    """For each true star, whether a detection lies within ``radius`` px."""
    if len(found) == 0:
        return np.zeros(len(xy), bool)
    return cKDTree(found.xy).query(xy)[0] < radius


def _brightest_found(found, xy, flux, n, clear=None, margin_px=15.0):
    """Whether each of the n brightest stars at least ``margin_px`` from the foreground
    (False pixels of ``clear``) was found (nearer ones merge with it or see it in their
    annulus)."""
    from scipy import ndimage

    if clear is not None:
        far = ndimage.distance_transform_edt(clear) > margin_px
        keep = far[xy[:, 1].astype(int), xy[:, 0].astype(int)]
        xy, flux = xy[keep], flux[keep]
    return _found(found, xy[np.argsort(-flux)[:n]])


def _on(found, where: np.ndarray, grow_px: int = 2) -> np.ndarray:
    """Per detection: whether it lies on (or within ``grow_px`` of) a True pixel of where."""
    if len(found) == 0:
        return np.zeros(0, bool)
    from scipy import ndimage

    near = ndimage.binary_dilation(where, iterations=grow_px)
    col, row = np.clip(found.xy.astype(int).T, 0, SIZE - 1)
    return near[row, col]


def _horizon_glow() -> np.ndarray:
    """Sky light rising towards the bottom of the frame (e per px): 80 at the top, 2080 at
    the bottom, as in a photograph low over a town."""
    y = np.arange(SIZE, dtype=float)[:, None] + 0.5
    return np.broadcast_to(80.0 + 2000.0 * np.exp(-(SIZE - y) / 150.0), (SIZE, SIZE))


def _tree(rng: np.random.Generator) -> np.ndarray:
    """A canopy (True where the tree hides the sky) over the lower left: overlapping crowns
    with branches reaching into the sky and small holes of sky through the leaves."""
    rows, cols = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    tree = np.zeros((SIZE, SIZE), bool)
    for _ in range(14):
        cx, cy, r = rng.uniform(0, 260), rng.uniform(300, SIZE + 40), rng.uniform(40, 90)
        tree |= np.hypot(cols - cx, rows - cy) < r
    for _ in range(10):  # branches: thin lines into the sky
        x0, y0 = rng.uniform(60, 240), rng.uniform(300, 420)
        angle, length = rng.uniform(-2.6, -0.5), rng.uniform(60, 140)
        t = np.linspace(0, length, 400)
        bx, by = x0 + t * np.cos(angle), y0 + t * np.sin(angle)
        inside = (bx >= 0) & (bx < SIZE) & (by >= 0) & (by < SIZE)
        tree[by[inside].astype(int), bx[inside].astype(int)] = True
    for _ in range(60):  # holes of sky in the leaves, 1-4 px
        cx, cy, r = rng.uniform(0, 250), rng.uniform(330, SIZE), rng.uniform(0.7, 2.0)
        tree &= ~(np.hypot(cols - cx, rows - cy) < r)
    return tree


def _lit(mask: np.ndarray, sky: np.ndarray, rng: np.random.Generator, fraction: float):
    """Foreground light: ``fraction`` of the sky glow, with blotchy texture (leaves, tiles)."""
    from scipy import ndimage

    texture = ndimage.gaussian_filter(rng.normal(size=mask.shape), 1.5)
    texture = 1.0 + 2.0 * texture / texture.std() * 0.35
    return np.where(mask, fraction * sky * np.clip(texture, 0.1, None), 0.0)


@pytest.mark.parametrize("lit", [0.15, 1.5], ids=["dark-silhouette", "lit-foliage"])
def test_tree_against_horizon_glow(lit):
    """A tree over a glowing horizon, dark against it or lit brighter than the sky: the
    stars, not the leaves, the branches or the sky through the leaves, come first (and at
    most a tenth of what is handed on is foreground); the PSF width is the stars' (the
    foreground once gave 9 px for stars of 1.7 px)."""
    rng = np.random.default_rng(21)
    sky = _horizon_glow()
    tree = _tree(rng)
    xy, flux = _stars(rng, 40, clear=~tree)
    electrons = _optics(np.where(tree, 0.0, sky) + _lit(tree, sky, rng, lit), 1.7)
    electrons += star_electrons(xy, flux, SIZE, SIZE, 1.7)
    found = detect_stars(_exposed(electrons, rng), max_stars=50)
    assert found.psf_sigma_px == pytest.approx(1.7, rel=0.2)
    # a star whose annulus (8 PSF sigmas, 14 px) reaches the tree is judged by the tree
    assert _brightest_found(found, xy, flux, 15, ~tree, margin_px=20.0).all()
    on_tree = _on(found, tree, 2)
    assert not on_tree[:15].any() and on_tree.mean() <= 0.1  # the first 15 are all stars


def test_roof_edge_across_the_frame():
    """A lit roof cuts the frame diagonally, with a sharp bright edge and a gutter: every
    bright star found, none of the first 20 on the roof (at most a tenth of all)."""
    rng = np.random.default_rng(22)
    rows, cols = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    roof = cols > 330 + 0.3 * rows
    gutter = np.abs(cols - (330 + 0.3 * rows)) < 3.0
    sky = np.full((SIZE, SIZE), 150.0)
    xy, flux = _stars(rng, 30, clear=~roof)
    electrons = np.where(roof, 600.0, sky) + np.where(gutter, 3000.0, 0.0)
    electrons = _optics(electrons + _lit(roof, sky, rng, 2.0), 1.2)
    electrons += star_electrons(xy, flux, SIZE, SIZE, 1.2)
    found = detect_stars(_exposed(electrons, rng), max_stars=50)
    assert _brightest_found(found, xy, flux, 20, ~roof).all()
    on_roof = _on(found, roof | gutter, 2)
    assert not on_roof[:20].any() and on_roof.mean() <= 0.1
    assert found.psf_sigma_px == pytest.approx(1.2, rel=0.2)


def _trail_mask(x0, y0, x1, y1, width_px):
    rows, cols = np.mgrid[0:SIZE, 0:SIZE] + 0.5
    d = np.array([x1 - x0, y1 - y0]) / np.hypot(x1 - x0, y1 - y0)
    across = np.abs((cols - x0) * d[1] - (rows - y0) * d[0])
    return across, across < width_px


@pytest.mark.parametrize("bright", [False, True], ids=["satellite", "aircraft-saturated"])
def test_trails_are_not_stars(bright):
    """A satellite trail (faint, PSF-wide) and a saturated aircraft trail with its blinking
    lights: no detection on the trail, the stars beside it found."""
    rng = np.random.default_rng(23)
    across, trail = _trail_mask(0.0, 80.0, SIZE, 430.0, 4.0)
    xy, flux = _stars(rng, 40, clear=~trail, margin=6.0)
    per_px = 4e4 if bright else 250.0  # e per px of length
    electrons = np.full((SIZE, SIZE), 100.0) + star_electrons(xy, flux, SIZE, SIZE, 1.0)
    electrons += per_px / np.sqrt(2 * np.pi) * np.exp(-0.5 * across**2)
    if bright:  # navigation lights along the trail
        t = np.linspace(0.1, 0.9, 6)[:, None]
        lights = np.column_stack([t[:, 0] * SIZE, 80.0 + t[:, 0] * 350.0])
        electrons += star_electrons(lights, np.full(len(lights), 3e5), SIZE, SIZE, 1.5)
    found = detect_stars(_exposed(electrons, rng), max_stars=60)
    assert not _on(found, trail, 2).any()
    assert _brightest_found(found, xy, flux, 25, ~trail).all()


@pytest.mark.parametrize("sigma", [0.5, 0.65, 0.8])
def test_hot_pixels_beside_undersampled_stars(sigma):
    """Undersampled stars centred on pixels (the case that looks most like a hot pixel),
    from the detection limit up, with hot and warm pixels around them and beside them: no
    star is removed as a hot pixel, no hot pixel is handed on."""
    rng = np.random.default_rng(24)
    xy = np.floor(_grid(8, SIZE, rng)) + 0.5  # pixel centres
    snr = np.geomspace(8.0, 300.0, len(xy))
    noise = np.sqrt(100.0 + READ_NOISE_E**2)
    flux = snr * noise * np.sqrt(4 * np.pi) * sigma
    electrons = np.full((SIZE, SIZE), 100.0) + star_electrons(xy, flux, SIZE, SIZE, sigma)
    image = _exposed(electrons, rng).astype(np.float64)
    # the stars found in the frame without hot pixels and without the rule: the rule must
    # keep every one of them (and all from SNR 12 up are found)
    detectable = _found(detect_stars(image, reject_hot_pixels=False), xy, 1.0)
    assert detectable[snr >= 12].all()
    hot = np.column_stack([rng.integers(5, SIZE - 5, 60), rng.integers(5, SIZE - 5, 60)])
    hot[:16] = np.floor(xy[:16] + np.array([4.0, 0.0])).astype(int)  # four px beside a star
    hot = hot[cKDTree(xy).query(hot + 0.5)[0] > 3.5]
    image[hot[:, 1], hot[:, 0]] += np.geomspace(15 * noise, 2e4, len(hot))  # warm to hot
    found = detect_stars(image)
    assert _found(found, xy, 1.0)[detectable].all()
    assert cKDTree(hot + 0.5).query(found.xy)[0].min() > 1.5  # no hot pixel
    assert found.n_hot >= len(hot) - 2


def test_compressed_colour_jpeg(tmp_path):
    """A colour photograph of coloured stars on a tinted sky gradient, gamma-encoded and
    saved as a JPEG (quality 80, chroma subsampled), read back as luminance: the bright
    stars come first and centroid within 0.25 px."""
    rng = np.random.default_rng(25)
    xy, flux = _stars(rng, 40)
    colour = rng.uniform(0.5, 1.0, (len(xy), 3))
    y = np.arange(SIZE)[:, None] / SIZE
    planes = []
    for k, tint in enumerate((1.0, 0.8, 1.3)):
        stars = star_electrons(xy, flux * colour[:, k], SIZE, SIZE, 1.1)
        planes.append(tint * (300.0 + 500.0 * y) + stars)
    linear = np.stack(planes, -1)
    noisy = rng.poisson(linear) + rng.normal(0, READ_NOISE_E, linear.shape)
    encoded = 255.0 * np.clip(noisy / 12000.0, 0, 1) ** (1 / 2.2)
    Image.fromarray(np.rint(encoded).astype(np.uint8)).save(tmp_path / "c.jpg", quality=80)
    found = detect_stars(read_image(tmp_path / "c.jpg"), max_stars=50)
    top = np.argsort(-flux)[:20]
    hit = _found(found, xy[top], 1.5)
    assert hit.all()
    offsets = found.xy[cKDTree(found.xy).query(xy[top])[1]] - xy[top]
    assert np.sqrt(np.mean(offsets**2)) < 0.25
    assert _found(found, xy, 1.5).sum() >= 0.9 * min(len(found), len(xy))  # few false ones


def test_clouds_and_moonlight():
    """Moonlight across the frame (sky 100 to 3000 e px) and bright, sharp-edged clouds
    that dim the stars behind them: no detection on the clouds, the stars in the clear
    found first."""
    from scipy import ndimage

    rng = np.random.default_rng(26)
    cols = np.mgrid[0:SIZE, 0:SIZE][1] + 0.5
    moon = 100.0 + 2900.0 * (cols / SIZE) ** 2
    cloud = ndimage.gaussian_filter(rng.normal(size=(SIZE, SIZE)), 25.0)
    cloud = np.clip((cloud / cloud.std() - 0.8) * 2.0, 0.0, 1.0)  # patches, soft edges
    xy, flux = _stars(rng, 50)
    behind = cloud[xy[:, 1].astype(int), xy[:, 0].astype(int)]
    electrons = moon * (1.0 + 1.5 * cloud)
    electrons += star_electrons(xy, flux * (1.0 - 0.9 * behind), SIZE, SIZE, 1.0)
    found = detect_stars(_exposed(electrons, rng), max_stars=40)
    clear = behind < 0.05
    # (a star within ~25 px of a cloud's edge can sit in what the background leaves of it)
    assert _brightest_found(found, xy[clear], flux[clear], 15, cloud < 0.05, 25.0).all()
    assert _found(found, xy, 2.0).sum() >= 0.95 * len(found)  # no cloud edge taken for a star
    which = cKDTree(xy).query(found.xy)[0] < 2.0
    assert which[:10].all()


@pytest.fixture
def small_sep_buffers():
    """sep's pixel stack and sub-object limit set far below its defaults (restored after)."""
    import sep

    pixstack, sub_objects = sep.get_extract_pixstack(), sep.get_sub_object_limit()
    sep.set_extract_pixstack(60)
    sep.set_sub_object_limit(1)
    yield sep
    sep.set_extract_pixstack(pixstack)
    sep.set_sub_object_limit(sub_objects)


def _blended_pairs(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """A 256 px frame of 49 pairs of stars 5 px apart: one source each above the threshold,
    which sep's deblending splits into two."""
    xy = _grid(7, 256, rng)
    xy = np.vstack([xy, xy + np.array([5.0, 0.0])])
    flux = rng.uniform(1e4, 5e4, len(xy))
    return render_stars(xy, flux, 256, 256, RenderSettings(), rng), xy


def test_sep_buffer_limits_are_raised_not_passed_on(small_sep_buffers):
    """A crowded field that fills sep's buffers (here made small) is detected as with sep's
    defaults: the limits are raised for the call, and put back after it."""
    sep = small_sep_buffers
    image, xy = _blended_pairs(np.random.default_rng(31))
    with pytest.raises(Exception, match=r"buffer full|deblending overflow"):
        sep.extract(image - np.median(image), 50.0, deblend_nthresh=16)
    found = detect_stars(image)
    assert (sep.get_extract_pixstack(), sep.get_sub_object_limit()) == (60, 1)
    sep.set_extract_pixstack(300_000)
    sep.set_sub_object_limit(1024)
    assert np.array_equal(found.xy, detect_stars(image).xy)
    assert (_match(found.xy, xy, 2.0)[0] >= 0).sum() >= 0.9 * len(xy)  # the pairs are split


def test_sep_limits_at_their_bound_raise_the_threshold(small_sep_buffers, monkeypatch):
    """When the buffers may not grow enough (here: pairs that always need 3 sub-objects), the
    threshold doubles, three times at most, and then the frame has no stars: the cost is
    bounded and no error reaches the caller."""
    import starnav.detect.stars as stars

    sep = small_sep_buffers
    monkeypatch.setattr(stars, "_SEP_MAX_SUB_OBJECTS", 2)
    thresholds, sep_extract = [], sep.extract

    def extract(data, thresh, **kwargs):
        thresholds.append(thresh)
        return sep_extract(data, thresh, **kwargs)

    monkeypatch.setattr(sep, "extract", extract)
    image, _ = _blended_pairs(np.random.default_rng(32))
    assert len(detect_stars(image, psf_sigma_px=1.0)) == 0
    tried = np.array(thresholds[:-1]) / thresholds[0]  # the last call makes sep's empty answer
    assert np.allclose(tried[-4:], [1, 2, 4, 8]) and tried.max() == 8


def test_sky_clipped_at_the_black_level():
    """An 8-bit star-tracker frame whose sky was cut at the black level (half its pixels 0),
    with a glow along one edge: its noise is the upper half-width of its values, not the
    clipped rms (0.03 ADU here), so the glow is not taken for one huge source (which took sep
    seconds) and the stars are found, the brightest first."""
    rng = np.random.default_rng(33)
    cols = np.mgrid[0:SIZE, 0:SIZE][1] + 0.5
    glow = 40.0 * np.exp(-(SIZE - cols) / 40.0)  # e per px, along the right edge
    xy, flux = _stars(rng, 40)
    electrons = 4.0 + glow + star_electrons(xy, flux / 20.0, SIZE, SIZE, 1.0)
    noisy = rng.poisson(electrons) + rng.normal(0.0, 1.0, electrons.shape)
    image = np.clip(np.rint(noisy - 5.0), 0, 255).astype(np.uint8)  # the black level cut
    assert np.mean(image == 0) > 0.4
    found = detect_stars(image, max_stars=30)
    assert found.background_rms > 1.0  # (sigma-clipped, the clipped sky says 0.03 ADU)
    assert _brightest_found(found, xy, flux, 15).all()
    assert _found(found, xy, 2.0).sum() >= 0.9 * len(found)


def test_bloated_bright_stars_of_a_stretched_photograph(tmp_path):
    """A deep, stretched colour photograph (8-bit JPEG, noise ~15 levels): its five brightest
    stars are discs with halos 5-7 PSF sigmas wide, their cores clipped near 255 in each
    colour; faint stars crowd the field. The bloated stars are found, and first."""
    rng = np.random.default_rng(34)
    xy, flux = _stars(rng, 150)
    inner = np.flatnonzero((np.abs(xy - SIZE / 2) < SIZE / 2 - 40).all(axis=1))
    bright = inner[np.argsort(-flux[inner])[:5]]  # whole discs, not cut by the edge
    width = rng.uniform(5.0, 7.0, len(bright))
    planes = []
    for tint in (1.0, 0.9, 1.1):
        sky = np.full((SIZE, SIZE), 400.0 * tint)
        faint = np.setdiff1d(np.arange(len(xy)), bright)
        sky += star_electrons(xy[faint], flux[faint] * tint, SIZE, SIZE, 1.2)
        for i, s in zip(bright, width, strict=True):  # a disc and a halo far over the range
            sky += star_electrons(xy[i : i + 1], np.array([3e7 * tint]), SIZE, SIZE, s)
        planes.append(sky)
    linear = np.stack(planes, -1)
    noisy = rng.poisson(linear) + rng.normal(0, 20.0, linear.shape)
    stretched = 255.0 * np.clip(np.arcsinh((noisy - 300.0) / 300.0) / 3.2, 0, 1)
    Image.fromarray(np.rint(stretched).astype(np.uint8)).save(tmp_path / "d.jpg", quality=85)
    found = detect_stars(read_image(tmp_path / "d.jpg"), max_stars=50)
    assert _found(found, xy[bright], 3.0).all()
    assert (cKDTree(xy[bright]).query(found.xy[:5])[0] < 3.0).all()


def test_quiet_8_bit_sky_is_not_foreground():
    """An 8-bit sky whose noise is under 2 levels (a dark site, a short exposure: what a
    small camera's JPEG holds): the median absolute deviation of its whole-number pixel steps
    reads 1.05 where their rms is 1.57, which once made star annuli look rough ("in
    foreground"). Every star well above the threshold is found."""
    from scipy import ndimage

    rng = np.random.default_rng(35)
    xy, flux = _stars(rng, 40)
    flux = np.exp(rng.uniform(np.log(150.0), np.log(3000.0), len(xy)))
    sky = 20.0 + star_electrons(xy, flux, SIZE, SIZE, 1.3)
    # rms 1.8 levels, smoothed (correlation 1.16) as a JPEG's: steps of rms 1.57, MAD 1.05
    noise = ndimage.gaussian_filter(rng.normal(0.0, 2.8, sky.shape), 0.5)
    image = np.clip(np.rint(sky + noise), 0, 255).astype(np.uint8)
    found = detect_stars(image)
    peak = flux / (2 * np.pi * 1.3**2)
    clear = peak > 15 * 1.8  # 15 sigmas at the peak
    assert _found(found, xy[clear], 1.0).mean() >= 0.95


def test_a_saturated_patch_cut_into_pieces_is_not_stars():
    """A lamp's glare in a corner of an all-sky frame cut by the deblender into round
    saturated pieces (here a 5 x 5 grid of saturated spots 6 px apart): ``without_glare``
    drops the pieces with 5 or more saturated others within 1.5 % of the diagonal, so that
    the isolated saturated stars and the faint stars rank first, as on the Crimean meteor
    camera's frame (its corner lamp was its 20 brightest sources)."""
    settings = RenderSettings(seed=23)
    stars = np.array([[100.5, 80.5], [300.5, 250.5], [480.5, 120.5], [200.5, 330.5]])
    grid = np.array([[540.5 + 6 * i, 330.5 + 6 * j] for i in range(5) for j in range(5)])
    xy = np.vstack([stars, grid])
    flux = np.concatenate([[3e6, 5e6, 4e6, 2e4], np.full(len(grid), 3e6)])
    image = render_stars(xy, flux, 600, 400, settings)
    assert len(detect_stars(image)) == len(xy)  # each piece is a star to detect_stars alone
    found = without_glare(detect_stars(image))  # as an all-sky frame's detection takes them
    which, _ = _match(found.xy, xy)
    assert which[:3].tolist() == [1, 2, 0] and 3 in which  # the saturated stars first
    pieces = which[which >= len(stars)]
    assert len(pieces) <= 4  # of 25: the grid's corners (3 others in reach) at most


def _listed(xy: np.ndarray, width: int = 3000, height: int = 2000) -> Detections:
    """Detections at ``xy`` (brightest first), nothing else measured."""
    n = len(xy)
    ones = np.ones(n)
    return Detections(np.asarray(xy, float), ones, ones, ones[::-1].cumsum(),
                      np.zeros(n, bool), 0.0, 1.0, 1.0, 0, 0, width, height)  # fmt: skip


def test_a_chopped_trail_is_not_stars_and_stars_are_kept():
    """A fireball chopped into round dashes by a shutter (the Desert Fireball Network's
    frames: 14-32 of the 100 brightest sources) lies on a line, evenly: ``without_trails``
    drops the dashes; random stars, however dense, and three stars in a row stay."""
    rng = np.random.default_rng(12)
    stars = rng.uniform([0, 0], [3000, 2000], size=(300, 2))
    t = np.arange(14.0)
    trail = np.column_stack([900 + 13.0 * t, 430 - 1.3 * t]) + rng.normal(0, 0.3, (14, 2))
    row = np.array([[2500.0, 1500.0], [2520.0, 1500.0], [2540.0, 1500.0]])
    found = without_trails(_listed(np.vstack([trail, stars, row])))
    assert len(found) == len(stars) + len(row)
    assert not np.isin(found.xy, trail).all(axis=1).any()
    for seed in range(20):  # dense fields: nothing taken for a trail
        dense = np.random.default_rng(seed).uniform([0, 0], [3000, 2000], size=(500, 2))
        assert len(without_trails(_listed(dense))) == 500
