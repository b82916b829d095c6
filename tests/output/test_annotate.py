"""Bright-star names (checked against Hipparcos) and the annotated PNG of a solved image."""

import numpy as np
import pytest
from PIL import Image

from starnav.camera import Camera
from starnav.catalog import Catalog, load_catalog
from starnav.catalog.names import star_names
from starnav.errors import ImageError, StarnavError
from starnav.geometry import angle_between, attitude_from_radec_roll, radec_to_unit
from starnav.output.annotate import annotate_image, annotation_figure, figure_size_px
from starnav.simulate import project_catalog

# J2000 positions (degrees) of stars whose coordinates every almanac lists
KNOWN_J2000 = {
    "Sirius": (101.287, -16.716),
    "Canopus": (95.988, -52.696),
    "Arcturus": (213.915, 19.182),
    "Vega": (279.235, 38.784),
    "Capella": (79.172, 45.998),
    "Rigel": (78.634, -8.202),
    "Procyon": (114.825, 5.225),
    "Betelgeuse": (88.793, 7.407),
    "Achernar": (24.429, -57.237),
    "Altair": (297.696, 8.868),
    "Aldebaran": (68.980, 16.509),
    "Polaris": (37.955, 89.264),
    "Deneb": (310.358, 45.280),
    "Antares": (247.352, -26.432),
    "Fomalhaut": (344.413, -29.622),
}


@pytest.fixture(scope="module")
def hip():
    return load_catalog(None, mag_limit=4.5, epoch_year=2000.0)


def test_every_named_star_is_a_bright_hipparcos_star(hip):
    names = star_names()
    assert 100 <= len(names) <= 150
    assert len(set(names.values())) == len(names)
    rows = hip.rows(list(names))  # CatalogError naming the first HIP number it lacks
    assert hip.mag[rows].max() < 3.5
    # the 50 brightest stars of the sky are all named but gamma2 Velorum ("Regor" is no IAU name)
    brightest = hip.ids[np.argsort(hip.mag)[:50]]
    assert set(brightest.tolist()) - set(names) == {39953}
    assert names[32349] == "Sirius" and names[30438] == "Canopus" and names[11767] == "Polaris"


def test_named_stars_sit_where_the_almanac_puts_them(hip):
    by_name = {name: hip_id for hip_id, name in star_names().items()}
    for name, (ra, dec) in KNOWN_J2000.items():
        row = hip.rows([by_name[name]])[0]
        error = np.degrees(angle_between(hip.vectors[row], radec_to_unit(*np.radians([ra, dec]))))
        assert error < 0.1, name


def test_star_names_returns_a_copy():
    names = star_names()
    names.clear()
    assert len(star_names()) > 100


def _render(catalog, R, camera, rng, *, sigma_px=1.3, sky_e=200.0, read_noise_e=8.0):
    """Gaussian stars at their exact pixels, sky, shot and read noise (a rendered-like image)."""
    rows, xy = project_catalog(catalog, R, camera)
    image = np.full((camera.height, camera.width), sky_e)
    half = 6
    for (x, y), mag in zip(xy, catalog.mag[rows], strict=True):
        cols = np.arange(int(x) - half, int(x) + half + 1)
        lines = np.arange(int(y) - half, int(y) + half + 1)
        cols, lines = cols[(cols >= 0) & (cols < camera.width)], lines[lines >= 0]
        lines = lines[lines < camera.height]
        r2 = (cols[None, :] + 0.5 - x) ** 2 + (lines[:, None] + 0.5 - y) ** 2
        flux = 2e5 * 10 ** (-0.4 * mag) / (2 * np.pi * sigma_px**2)
        image[np.ix_(lines, cols)] += flux * np.exp(-r2 / (2 * sigma_px**2))
    return rng.poisson(image) + rng.normal(0.0, read_noise_e, image.shape), rows, xy


@pytest.fixture(scope="module")
def orion():
    """A 640 x 480, 25° frame on Orion's belt, its detections and matches at a solution
    slightly off the truth (so the residuals are not zero)."""
    catalog = load_catalog(None, mag_limit=6.5)
    camera = Camera.from_fov(25.0, 640, 480)
    rng = np.random.default_rng(7)
    truth = attitude_from_radec_roll(83.0, 0.0, 20.0, 1)
    image, rows, xy = _render(catalog, truth, camera, rng)
    bright = catalog.mag[rows] < 5.0
    detected = xy[bright] + rng.normal(0.0, 0.2, (bright.sum(), 2))
    detected = np.vstack([detected, [[40.0, 40.0]]])  # not a star
    solution = attitude_from_radec_roll(83.003, 0.001, 20.02, 1)
    ids = catalog.ids[rows[bright]]
    predicted = camera.bearings_to_pixels(catalog.vectors[rows[bright]] @ solution.T)
    matched = np.column_stack([detected[:-1], ids, predicted - detected[:-1]])
    return dict(
        image=image,
        detected_xy=detected,
        R_cam_from_icrs=solution,
        camera=camera,
        catalog=catalog,
        matched=matched,
    )


def test_figure_labels_named_stars_ids_and_solution(orion):
    fig = annotation_figure(**orion, title="synthetic Orion")
    ax = fig.axes[0]
    texts = [t.get_text() for t in ax.texts]
    for name in ("Betelgeuse", "Rigel", "Alnilam", "Bellatrix"):
        assert name in texts
    assert "Sirius" not in texts and "Capella" not in texts  # not in view
    ids = {str(int(i)) for i in orion["matched"][:, 2]}
    assert ids <= set(texts)
    assert str(27989) in ids  # Betelgeuse is matched and carries its HIP number
    title = " ".join(t.get_text() for t in fig.texts)
    assert "synthetic Orion" in title and "RA 83.0030°" in title and "Dec +0.0010°" in title
    assert "roll 20.020°" in title and "FOV 25.000°" in title and "parity +1" in title
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert any("x50" in t for t in legend)
    image = ax.images[0]
    assert tuple(image.get_extent()) == (0, 640, 480, 0)
    assert ax.get_ylim() == (480, 0)  # y down


def test_png_written_with_the_expected_size(orion, tmp_path):
    path = tmp_path / "orion.png"
    annotate_image(path, **orion, residual_scale=20.0)
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with Image.open(path) as png:
        assert png.size == figure_size_px(640, 480, title_lines=1)
        assert png.size == (1024, 768 + 32)  # small images are enlarged to 1024 px
        pixels = np.asarray(png.convert("RGB"))
    assert pixels.std() > 10  # a picture, not a blank page


def test_big_image_is_scaled_down():
    assert figure_size_px(4096, 3072) == (1600, 1200 + 32)
    assert figure_size_px(1000, 6000, title_lines=2) == (267, 1600 + 52)
    assert figure_size_px(1200, 800) == (1200, 800 + 32)


def _far_catalog():
    """Three stars far from the pointing used below: nothing drawn but the image."""
    return Catalog(
        np.array([1, 2, 3]), np.array([200.0, 210.0, 220.0]), np.array([-60.0, -61.0, -62.0]),
        np.array([1.0, 2.0, 3.0]), "three far stars",
    )  # fmt: skip


def test_pixel_convention_of_the_drawn_image(tmp_path):
    """A hot pixel at (row 100, col 301) shows centred on (x, y) = (301.5, 100.5), scaled."""
    camera = Camera.from_fov(10.0, 512, 384)
    image = np.random.default_rng(1).normal(100.0, 3.0, (384, 512))
    image[100, 301] = 5000.0
    path = tmp_path / "hot.png"
    annotate_image(
        path,
        image,
        detected_xy=np.empty((0, 2)),
        R_cam_from_icrs=attitude_from_radec_roll(10.0, 20.0, 0.0),
        camera=camera,
        catalog=_far_catalog(),
        matched=[],
    )
    with Image.open(path) as png:
        gray = np.asarray(png.convert("L"), dtype=float)
    strip = gray.shape[0] - 768  # title strip above the image, scale 2
    picture = gray[strip:]
    hot = np.argwhere(picture > 0.9 * picture.max())
    centre = hot.mean(axis=0) + 0.5  # PNG pixel centres
    assert np.allclose(centre, [2 * 100.5, 2 * 301.5], atol=0.6)


def test_names_only_for_hipparcos_ids_unless_given(orion):
    renamed = Catalog(
        orion["catalog"].ids,
        orion["catalog"].ra_deg,
        orion["catalog"].dec_deg,
        orion["catalog"].mag,
        "my.csv",
    )
    args = {**orion, "catalog": renamed}
    texts = [t.get_text() for t in annotation_figure(**args).axes[0].texts]
    assert "Betelgeuse" not in texts
    texts = [
        t.get_text() for t in annotation_figure(**args, names={27989: "Alpha Ori"}).axes[0].texts
    ]
    assert "Alpha Ori" in texts


def test_bad_input_is_refused(orion):
    with pytest.raises(ImageError, match="does not match the camera"):
        annotation_figure(**{**orion, "image": orion["image"].T})
    with pytest.raises(StarnavError, match="matched must be rows"):
        annotation_figure(**{**orion, "matched": orion["matched"][:, :3]})
    with pytest.raises(StarnavError, match="detected_xy"):
        annotation_figure(**{**orion, "detected_xy": np.zeros((3, 3))})
    with pytest.raises(StarnavError, match="3x3"):
        annotation_figure(**{**orion, "R_cam_from_icrs": np.eye(2)})
    with pytest.raises(StarnavError, match="residual_scale"):
        annotation_figure(**orion, residual_scale=0.0)


def test_a_large_image_is_binned_before_it_is_drawn_in_place(tmp_path):
    """A 6400 x 4800 image drawn 1600 px wide: binned 4 x 4 before matplotlib (no full-size
    copies), a bright 4 x 4 block still where it is, at a quarter of its coordinates."""
    camera = Camera.from_fov(10.0, 6400, 4800)
    image = np.random.default_rng(2).normal(100.0, 3.0, (4800, 6400)).astype(np.float32)
    image[1200:1204, 3000:3004] = 5000.0  # edges 3000-3004, 1200-1204: centre (3002, 1202)
    path = tmp_path / "large.png"
    annotate_image(path, image, detected_xy=np.empty((0, 2)),
                   R_cam_from_icrs=attitude_from_radec_roll(10.0, 20.0, 0.0), camera=camera,
                   catalog=_far_catalog(), matched=[])  # fmt: skip
    with Image.open(path) as png:
        gray = np.asarray(png.convert("L"), dtype=float)
    picture = gray[gray.shape[0] - 1200 :]  # below the title strip
    hot = np.argwhere(picture > 0.9 * picture.max())
    assert np.allclose(hot.mean(axis=0) + 0.5, [1202 / 4, 3002 / 4], atol=0.6)
