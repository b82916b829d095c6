"""Star images from frames: what a star camera's sensor would record.

Model, per pixel, in electrons: stars drawn with a Gaussian PSF *integrated over the pixel
area* (differences of erf, so a star's light sums to its flux whatever its sub-pixel phase),
plus a flat sky + dark level; photon (Poisson) noise on both, Gaussian read noise, conversion to
ADU by the gain, hot pixels (single bright pixels), quantisation and clipping at the full scale
of the bit depth (saturation; there is no bias level, so values below 0 ADU clip at 0). Stars
whose centre lies up to 5 PSF sigmas outside the image are drawn too (their light spills in),
but only stars centred inside are listed as the truth.

Pixel convention (docs/conventions.md): origin at the top-left corner of the image, x right, y down;
the array is ``image[row=y, col=x]``, so a star at (x, y) = (10.5, 20.5) is centred on pixel
row 20, column 10. Any lens model (``starnav.camera``) places the stars: the directions it sees
go through its ``bearings_to_pixels`` (pinhole distortion, fisheye projections alike).

Fisheyes: pixels the lens forms no image on (outside its image circle, ``image_circle_deg``,
or beyond the radius its model reaches) receive neither sky nor starlight, only read noise: a
circular fisheye's image is a disc on black. Vignetting (``RenderSettings.vignetting_power``)
scales the sky and each star's flux by the relative illumination cos(θ/2)^p at the angle θ from
the optical axis. The PSF is the same Gaussian (``psf_sigma_px``) everywhere in the image, and
the sky is flat per pixel apart from the vignetting (a fisheye's pixels do not all cover the
same solid angle; that is not modelled).

Brightness: a star of magnitude m yields ``zero_point_e_per_s * exposure_s * 10**(-0.4 m)``
electrons. The defaults put an Hp 7 star at SNR ~ 11 (PSF sigma 1 px), so the 1024 px / 20°
reference camera sees to about Hp 7; stars brighter than Hp ~ -0.7 saturate at 16 bits.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from starnav.camera import Camera, CameraModel
from starnav.catalog import Catalog
from starnav.errors import ImageError, StarnavError, shown
from starnav.geometry import radec_roll_from_attitude
from starnav.runtime.csvrows import write_rows
from starnav.simulate import project_catalog

# Sky photons are drawn from the Gaussian of the same variance above this level (e/px): after
# adding read noise and quantising, the two are indistinguishable there, and it is 4x faster
# than Poisson on every pixel. Star photons are always drawn from Poisson.
_GAUSSIAN_SKY_E = 30.0
_STAMP_HALF_WIDTH_SIGMA = 5.0
_FITS_SUFFIXES = (".fits", ".fit", ".fts")
# cos(θ/2)^2 falls to 0.5 (one stop) at 90° from the axis: a typical all-sky fisheye
FISHEYE_VIGNETTING_POWER = 2.0
_ROUND_TRIP_PX = 1e-3  # a pixel the lens images unprojects and projects back within this
_ROUND_TRIP_RAD = 1e-6  # and a direction it images projects and unprojects back within this
_PILLOW_SUFFIXES = (".png", ".tif", ".tiff")


def _is_real(value) -> bool:
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def _is_int(value) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


@dataclass(frozen=True)
class RenderSettings:
    """Sensor and optics of a rendered frame.

    ``psf_sigma_px``: Gaussian PSF sigma (px); ``exposure_s`` (s); ``zero_point_e_per_s``:
    electrons per second from a magnitude-0 star; ``background_e``: sky + dark per pixel
    (electrons, over the exposure); ``read_noise_e`` (electrons rms); ``gain_e_per_adu``;
    ``bit_depth``: 8 or 16 (uint8 / uint16 output, clipped at 2**bit_depth - 1 ADU);
    ``hot_pixels``: how many single hot pixels at random places, each ``hot_pixel_adu`` above
    its surroundings (None: the full scale, i.e. saturated); ``mag_limit``: catalog stars
    fainter than this are not drawn (None: all); ``seed``: random seed (None: fresh entropy);
    ``vignetting_power``: p of the relative illumination cos(θ/2)^p that scales the sky and the
    star flux at the angle θ from the optical axis (0: none; p = 2 gives one stop at 90°, as
    all-sky fisheyes have; near the axis p = 16 matches the cos⁴θ law of a simple lens; None:
    ``FISHEYE_VIGNETTING_POWER`` for a fisheye, 0 for a pinhole).
    """

    psf_sigma_px: float = 1.0
    exposure_s: float = 0.1
    zero_point_e_per_s: float = 2.5e6
    background_e: float = 50.0
    read_noise_e: float = 5.0
    gain_e_per_adu: float = 1.0
    bit_depth: int = 16
    hot_pixels: int = 0
    hot_pixel_adu: float | None = None
    mag_limit: float | None = None
    seed: int | None = None
    vignetting_power: float | None = None

    def __post_init__(self) -> None:
        positive = ("psf_sigma_px", "exposure_s", "gain_e_per_adu")
        non_negative = ("zero_point_e_per_s", "background_e", "read_noise_e")
        for f in fields(self):
            value = getattr(self, f.name)
            if f.name in positive + non_negative and not _is_real(value):
                raise StarnavError(f"{f.name} must be a number, got {shown(value)}")
            if f.name in positive and not (np.isfinite(value) and value > 0):
                raise StarnavError(f"{f.name} must be positive, got {shown(value)}")
            if f.name in non_negative and not (np.isfinite(value) and value >= 0):
                raise StarnavError(f"{f.name} must be >= 0, got {shown(value)}")
        if not 0.1 <= self.psf_sigma_px <= 50.0:
            raise StarnavError(
                f"psf_sigma_px must be in 0.1..50 px, got {shown(self.psf_sigma_px)}"
            )
        if self.bit_depth not in (8, 16) or isinstance(self.bit_depth, bool):
            raise StarnavError(f"bit_depth must be 8 or 16, got {shown(self.bit_depth)}")
        if not (_is_int(self.hot_pixels) and self.hot_pixels >= 0):
            raise StarnavError(f"hot_pixels must be an integer >= 0, got {shown(self.hot_pixels)}")
        if self.hot_pixel_adu is not None and not (
            _is_real(self.hot_pixel_adu) and np.isfinite(self.hot_pixel_adu)
        ):
            raise StarnavError(
                f"hot_pixel_adu must be a number or None, got {shown(self.hot_pixel_adu)}"
            )
        if self.hot_pixel_adu is not None and self.hot_pixel_adu <= 0:
            raise StarnavError(f"hot_pixel_adu must be positive, got {shown(self.hot_pixel_adu)}")
        if self.mag_limit is not None and not (
            _is_real(self.mag_limit) and np.isfinite(self.mag_limit)
        ):
            raise StarnavError(
                f"mag_limit must be a finite magnitude or None, got {shown(self.mag_limit)}"
            )
        if self.seed is not None and not (_is_int(self.seed) and self.seed >= 0):
            raise StarnavError(f"seed must be an integer >= 0 or None, got {shown(self.seed)}")
        power = self.vignetting_power
        if power is not None and not (_is_real(power) and np.isfinite(power) and power >= 0):
            raise StarnavError(
                f"vignetting_power must be a number >= 0 or None, got {shown(power)}"
            )

    def vignetting_power_for(self, camera: CameraModel) -> float:
        """The vignetting power used with ``camera`` (``vignetting_power``, or its lens's
        default when None)."""
        if self.vignetting_power is not None:
            return float(self.vignetting_power)
        return 0.0 if camera.kind == "pinhole" else FISHEYE_VIGNETTING_POWER

    @property
    def full_scale_adu(self) -> int:
        """Largest pixel value (ADU): saturation."""
        return 2**self.bit_depth - 1

    def flux_e(self, mag: np.ndarray | float) -> np.ndarray:
        """Electrons collected from stars of magnitude ``mag`` over the exposure."""
        return self.zero_point_e_per_s * self.exposure_s * 10.0 ** (-0.4 * np.asarray(mag))

    @property
    def pixel_variance_e2(self) -> float:
        """Noise variance per pixel without a star (electrons²): sky, read noise, quantisation."""
        return self.background_e + self.read_noise_e**2 + self.gain_e_per_adu**2 / 12.0


def star_snr(flux_e: np.ndarray | float, settings: RenderSettings) -> np.ndarray:
    """Signal-to-noise ratio of stars of ``flux_e`` electrons: flux / sqrt(flux + A var_px)
    with the Gaussian PSF's noise-equivalent area A = 4 pi sigma² (what PSF fitting reaches)."""
    flux = np.asarray(flux_e, dtype=float)
    area = 4.0 * np.pi * settings.psf_sigma_px**2
    return flux / np.sqrt(flux + area * settings.pixel_variance_e2)


def flux_e_for_snr(snr: float, settings: RenderSettings) -> float:
    """The star flux (electrons) that ``star_snr`` rates at ``snr``."""
    if not (np.isfinite(snr) and snr > 0):
        raise StarnavError(f"snr must be positive, got {shown(snr)}")
    noise2 = 4.0 * np.pi * settings.psf_sigma_px**2 * settings.pixel_variance_e2
    # flux² = snr² (flux + noise2): the positive root
    return float(0.5 * (snr**2 + math.sqrt(snr**4 + 4.0 * snr**2 * noise2)))


PRESETS: dict[str, tuple[Camera, RenderSettings]] = {
    # the two reference cameras of domain.md (../shared/docs): the triangle evaluation (mag 6)
    # and the positioning set-up (stars to mag 7)
    "seed-512": (Camera.from_fov(12.0, 512, 512), RenderSettings(mag_limit=6.0)),
    "seed-1024": (Camera.from_fov(20.0, 1024, 1024), RenderSettings(mag_limit=7.0)),
}


def preset(name: str) -> tuple[Camera, RenderSettings]:
    """The camera and render settings of a named preset (see ``PRESETS``)."""
    try:
        return PRESETS[name]
    except KeyError:
        raise StarnavError(
            f"unknown render preset {name!r}; choose one of {', '.join(sorted(PRESETS))}"
        ) from None


@dataclass(frozen=True, eq=False)
class RenderedFrame:
    """A rendered image and its truth.

    ``image``: uint8 or uint16 array (height, width), row 0 at the top; ``xy`` (n, 2): exact
    pixel positions of the drawn stars centred inside the image, brightest first; their
    catalog ``ids``, ``mag`` and expected ``flux_e`` (electrons, after vignetting); ``hot_xy``
    (k, 2): centres of the hot pixels; the attitude, camera and settings used.
    """

    image: np.ndarray
    xy: np.ndarray
    ids: np.ndarray
    mag: np.ndarray
    flux_e: np.ndarray
    hot_xy: np.ndarray
    R_cam_from_icrs: np.ndarray
    camera: CameraModel
    settings: RenderSettings

    def to_dict(self) -> dict:
        """The truth as a JSON-ready dict: attitude, the camera's size, focal length, model
        coefficients (k1, k2 of a pinhole) and its camera file (``camera``), the vignetting
        power used, ``n_stars`` listed, the matrix (nested lists)."""
        ra, dec, roll, parity = radec_roll_from_attitude(self.R_cam_from_icrs)
        camera = self.camera.to_dict()
        flat = ("fov_deg", "width", "height", "focal_px")
        return {
            "ra_deg": ra,
            "dec_deg": dec,
            "roll_deg": roll,
            "parity": parity,
            "camera_model": self.camera.model,
            **{k: v for k, v in camera.items() if k in flat or k.startswith("k")},
            "camera": camera,
            "vignetting_power": self.settings.vignetting_power_for(self.camera),
            "n_stars": len(self.xy),
            "R_cam_from_icrs": self.R_cam_from_icrs.tolist(),
        }


def write_truth_csv(path: str | Path, frame: RenderedFrame) -> None:
    """The stars drawn (``x,y,catalog_id,mag``, brightest first) as CSV; ``StarnavError``
    when the file cannot be written."""
    rows = [
        [f"{x:.4f}", f"{y:.4f}", int(cid), f"{mag:.3f}"]
        for (x, y), cid, mag in zip(frame.xy, frame.ids, frame.mag, strict=True)
    ]
    write_rows(path, ["x", "y", "catalog_id", "mag"], rows)


def adjust_camera(
    camera: Camera,
    *,
    fov_deg: float | None = None,
    width: int | None = None,
    height: int | None = None,
    k1: float = 0.0,
    k2: float = 0.0,
) -> Camera:
    """``camera`` (a preset's) with the field of view and size given instead of its own (the
    height follows a new width unless given; the principal point is the centre then) and
    radial distortion ``k1``, ``k2``."""
    if fov_deg is not None or width is not None or height is not None:
        new_width = width or camera.width
        new_height = height or (new_width if width else camera.height)
        fov = camera.fov_deg if fov_deg is None else fov_deg
        camera = Camera.from_fov(fov, new_width, new_height)
    return Camera(camera.width, camera.height, camera.focal_px, camera.cx, camera.cy, k1, k2)


def star_electrons(
    xy: np.ndarray, flux_e: np.ndarray, width: int, height: int, psf_sigma_px: float
) -> np.ndarray:
    """Noise-free image (float64, height x width, electrons) of stars at ``xy`` (n, 2, px, our
    convention) with total ``flux_e`` (n,) electrons each, Gaussian PSF integrated per pixel."""
    flat, values = _star_pixels(xy, flux_e, width, height, psf_sigma_px)
    return np.bincount(flat, weights=values, minlength=width * height).reshape(height, width)


def render_stars(
    xy: np.ndarray,
    flux_e: np.ndarray,
    width: int,
    height: int,
    settings: RenderSettings,
    rng: np.random.Generator | int | None = None,
) -> np.ndarray:
    """Final image (uint8 / uint16 ADU, height x width) of stars at ``xy`` (n, 2, px, our
    convention) with ``flux_e`` (n,) electrons each, with every noise of ``settings``.
    ``rng``: a Generator or seed (None: ``settings.seed``)."""
    image, _ = _render(xy, flux_e, width, height, settings, settings.seed if rng is None else rng)
    return image


def render_frame(
    catalog: Catalog,
    camera: CameraModel,
    R_cam_from_icrs: np.ndarray,
    settings: RenderSettings | None = None,
) -> RenderedFrame:
    """Render the catalog stars that ``camera`` (any lens model) images at attitude
    ``R_cam_from_icrs``: pixels the lens forms no image on are black (read noise only), the
    sky and the stars are vignetted (``RenderSettings.vignetting_power``)."""
    settings = RenderSettings() if settings is None else settings
    R = np.asarray(R_cam_from_icrs, dtype=float)
    if R.shape != (3, 3):
        raise StarnavError(f"R_cam_from_icrs must be a 3x3 matrix, got shape {R.shape}")
    if settings.mag_limit is not None:
        catalog = catalog.brighter_than(settings.mag_limit)
    # a camera grown by the PSF margin on every side finds the stars whose light spills in
    margin = math.ceil(_STAMP_HALF_WIDTH_SIGMA * settings.psf_sigma_px)
    grown = dataclasses.replace(
        camera,
        width=camera.width + 2 * margin,
        height=camera.height + 2 * margin,
        cx=camera.cx + margin,
        cy=camera.cy + margin,
    )
    rows, xy = project_catalog(catalog, R, grown)
    c = catalog.vectors[rows] @ R.T
    imaged = imaged_directions(grown, c)  # the margin's stars spill light in too
    rows, xy, c = rows[imaged], xy[imaged] - margin, c[imaged]
    power = settings.vignetting_power_for(camera)
    flux = settings.flux_e(catalog.mag[rows]) * relative_illumination(c[:, 2], power)
    illumination = pixel_illumination(camera, power)
    image, hot_xy = _render(
        xy, flux, camera.width, camera.height, settings, settings.seed, illumination
    )
    inside = camera.contains(xy)
    order = np.argsort(catalog.mag[rows][inside], kind="stable")
    pick = np.flatnonzero(inside)[order]
    return RenderedFrame(
        image,
        xy[pick],
        catalog.ids[rows][pick],
        catalog.mag[rows][pick],
        flux[pick],
        hot_xy,
        R,
        camera,
        settings,
    )


def relative_illumination(cos_theta: np.ndarray, power: float) -> np.ndarray:
    """The vignetting factor cos(θ/2)^``power`` of directions whose angle θ from the
    optical axis has cosine ``cos_theta`` (1 on the axis; ``power`` 0: 1 everywhere)."""
    cos_half = np.sqrt(np.clip(0.5 * (1.0 + np.asarray(cos_theta, dtype=float)), 0.0, 1.0))
    return cos_half**power


def imaged_directions(camera: CameraModel, c: np.ndarray) -> np.ndarray:
    """Which unit camera-frame directions (n, 3) the lens forms an image of: those it ``sees``
    (inside the image and a fisheye's image circle) projected one to one (the direction's
    pixel unprojects back to it: an orthographic lens folds back past 90° from the axis)."""
    c = np.asarray(c, dtype=float).reshape(-1, 3)
    if camera.kind == "pinhole":  # one to one in front of it (``sees`` keeps those)
        return np.ones(len(c), dtype=bool)
    back = camera.pixels_to_bearings(camera.bearings_to_pixels(c))
    return (np.sum((back - c) ** 2, axis=1) < _ROUND_TRIP_RAD**2) & camera.sees(c)


@functools.lru_cache(maxsize=4)  # a series of frames of one camera computes it once
def pixel_illumination(camera: CameraModel, vignetting_power: float) -> np.ndarray | None:
    """The relative illumination (float32, height x width, read-only) of each pixel centre:
    0 where the lens forms no image (outside its image circle or beyond the radius its model
    reaches), else ``relative_illumination`` of the pixel's direction; None when it is 1
    everywhere (a pinhole without vignetting)."""
    if camera.kind == "pinhole" and vignetting_power == 0.0:
        return None
    cols, rows = np.meshgrid(np.arange(camera.width) + 0.5, np.arange(camera.height) + 0.5)
    xy = np.column_stack([cols.ravel(), rows.ravel()])
    c = camera.pixels_to_bearings(xy)
    values = relative_illumination(c[:, 2], vignetting_power)
    if camera.kind != "pinhole":  # a pinhole images its whole sensor
        # pixels past the largest radius of the model unproject to its last angle
        reached = np.sum((camera.bearings_to_pixels(c) - xy) ** 2, axis=1) < _ROUND_TRIP_PX**2
        values[~(reached & camera.sees(c))] = 0.0
    out = values.reshape(camera.height, camera.width).astype(np.float32)
    out.flags.writeable = False
    return out


def write_image(path: str | Path, image: np.ndarray) -> None:
    """Write a 2-D image: ``.png`` / ``.tif`` / ``.tiff`` through Pillow (uint8 or uint16 grey,
    16 bits kept; TIFF also float32), ``.fits`` / ``.fit`` / ``.fts`` through astropy (any
    numeric type). Row 0 of the array is the top of the picture; in FITS it is the first row
    stored (FITS y = 1), which FITS viewers show at the bottom. Overwrites an existing file."""
    path = Path(path)
    image = np.asarray(image)
    suffix = path.suffix.lower()
    if suffix not in _FITS_SUFFIXES + _PILLOW_SUFFIXES:
        raise ImageError(
            f"cannot write {str(path)!r}: unknown suffix {path.suffix!r} "
            "(use .png, .tif, .tiff, .fits, .fit or .fts)"
        )
    if image.ndim != 2 or image.size == 0:
        raise ImageError(f"cannot write {str(path)!r}: need a 2-D image, got shape {image.shape}")
    try:
        if suffix in _FITS_SUFFIXES:
            from astropy.io import fits

            if not (image.dtype.kind in "uif" and image.dtype.itemsize <= 8):
                raise ImageError(f"cannot write {str(path)!r} as FITS: dtype {image.dtype}")
            fits.PrimaryHDU(np.ascontiguousarray(image)).writeto(path, overwrite=True)
            return
        from PIL import Image

        allowed = (np.uint8, np.uint16) + ((np.float32,) if suffix != ".png" else ())
        if image.dtype.type not in allowed:
            kinds = ", ".join(np.dtype(t).name for t in allowed)
            raise ImageError(
                f"cannot write {str(path)!r}: dtype {image.dtype} (this format takes {kinds})"
            )
        # PNG: zlib level 1 writes a 16-bit 1024 px frame in ~40 ms instead of ~400 ms
        options = {"compress_level": 1} if suffix == ".png" else {}
        Image.fromarray(np.ascontiguousarray(image)).save(path, **options)
    except OSError as exc:
        raise ImageError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None


def _render(
    xy: np.ndarray,
    flux_e: np.ndarray,
    width: int,
    height: int,
    settings: RenderSettings,
    rng: np.random.Generator | int | None,
    illumination: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The image and the hot pixels' centres; ``illumination`` (height x width, see
    ``pixel_illumination``) scales the sky and drops the starlight where it is 0."""
    if not (_is_int(width) and _is_int(height) and width > 0 and height > 0):
        raise StarnavError(
            f"width and height must be positive integers, got {shown(width)} x {shown(height)}"
        )
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    flux_e = np.asarray(flux_e, dtype=float).reshape(-1)
    if len(flux_e) != len(xy):
        raise StarnavError(f"{len(xy)} star positions but {len(flux_e)} fluxes")
    if not (np.isfinite(xy).all() and np.isfinite(flux_e).all() and (flux_e >= 0).all()):
        raise StarnavError("star positions must be finite and fluxes finite and >= 0")
    rng = np.random.default_rng(rng)
    shape = (height, width)
    sky = np.float32(settings.background_e)
    if illumination is not None:
        sky = sky * illumination
    if settings.background_e >= _GAUSSIAN_SKY_E:
        electrons = rng.standard_normal(shape, dtype=np.float32)
        electrons *= np.sqrt(sky + np.float32(settings.read_noise_e**2))
        electrons += sky
    else:
        electrons = rng.poisson(sky, shape).astype(np.float32)
        if settings.read_noise_e:
            noise = rng.standard_normal(shape, dtype=np.float32)
            noise *= np.float32(settings.read_noise_e)
            electrons += noise
    flat, values = _star_pixels(xy, flux_e, width, height, settings.psf_sigma_px)
    if illumination is not None:
        lit = illumination.reshape(-1)[flat] > 0.0
        flat, values = flat[lit], values[lit]
    np.add.at(electrons.reshape(-1), flat, rng.poisson(values).astype(np.float32))
    adu = electrons
    if settings.gain_e_per_adu != 1.0:
        adu *= np.float32(1.0 / settings.gain_e_per_adu)
    full = settings.full_scale_adu
    hot = rng.choice(width * height, size=min(settings.hot_pixels, width * height), replace=False)
    level = full if settings.hot_pixel_adu is None else settings.hot_pixel_adu
    adu.reshape(-1)[hot] += np.float32(level)
    np.rint(adu, out=adu)
    np.clip(adu, 0, full, out=adu)
    image = adu.astype(np.uint8 if settings.bit_depth == 8 else np.uint16)
    hot_xy = np.column_stack([hot % width + 0.5, hot // width + 0.5]).astype(float)
    return image, hot_xy


def _star_pixels(
    xy: np.ndarray, flux_e: np.ndarray, width: int, height: int, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """Flat pixel indices and expected electrons of every star's PSF stamp inside the image."""
    from scipy.special import erf  # ~0.15 s to import: not when only the presets are read

    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    flux_e = np.asarray(flux_e, dtype=float).reshape(-1)
    half = math.ceil(_STAMP_HALF_WIDTH_SIGMA * sigma)
    offsets = np.arange(-half, half + 1)
    # pixel column c covers x in [c, c + 1): the stamp spans >= 5 sigma on both sides
    cols = np.floor(xy[:, :1]).astype(np.int64) + offsets
    rows = np.floor(xy[:, 1:]).astype(np.int64) + offsets
    scale = 1.0 / (math.sqrt(2.0) * sigma)
    edges = np.arange(-half, half + 2)
    ex = np.diff(erf((np.floor(xy[:, :1]) + edges - xy[:, :1]) * scale), axis=1) * 0.5
    ey = np.diff(erf((np.floor(xy[:, 1:]) + edges - xy[:, 1:]) * scale), axis=1) * 0.5
    values = flux_e[:, None, None] * ey[:, :, None] * ex[:, None, :]
    inside = ((rows >= 0) & (rows < height))[:, :, None] & ((cols >= 0) & (cols < width))[
        :, None, :
    ]
    flat = rows[:, :, None] * width + cols[:, None, :]
    return flat[inside], values[inside]
