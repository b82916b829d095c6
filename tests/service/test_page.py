"""The web page of ``starnav serve`` in a real headless browser (Chromium driven by selenium).

The server runs as ``starnav serve`` in a subprocess. Through the page: a real image solves to
its reference answer (tests/data/images/reference.json; the image: the Lyra frame of
tetra3 as a PNG, made from upstream's TIFF in ../shared/data) with the picture, the star table and
the downloads; the image's own detections pasted as x y lines solve too; an image with too few
stars fails with the reason and its unsolved picture, a file that is no image (dropped on the
page) with the reason alone; a server started with --api-key makes the page ask for the key,
and a job sent from it as private is shown on the page and hidden from other clients.

``STARNAV_SCREENSHOT=docs/images/serve_page.png`` also saves the solved page (docs/service.md).
"""

from __future__ import annotations

import base64
import io
import json
import math
import os
import socket
import sqlite3
import subprocess
import sys
import urllib.error
import urllib.request
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from selenium import webdriver
from selenium.common.exceptions import TimeoutException
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import Select, WebDriverWait

from shared_data import LYRA, PEER_REFERENCE, as_png, peer_image
from starnav.detect import read_image
from starnav.pipeline.image import detect_image
from starnav.service.app import wait_ready

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")
REFERENCE = PEER_REFERENCE[LYRA]
# the first solve of a fresh server builds the pattern tables of its private cache (~15 s alone
# with the field-size hint; the machine may be shared)
FIRST_SOLVE_S = 120.0
SOLVE_S = 60.0
BORESIGHT_TOL_ARCSEC = 60.0
ROLL_TOL_DEG = 0.1
API_KEY = "page-test-key"
SCREENSHOT_SCALE = 0.75

pytestmark = [
    pytest.mark.browser,
    pytest.mark.service,
    pytest.mark.slow,
    pytest.mark.skipif(
        not (CHROMIUM.exists() and CHROMEDRIVER.exists()),
        reason="chromium and chromium-driver not installed: apt-get install chromium "
        "chromium-driver",
    ),
]


@dataclass(frozen=True)
class Server:
    url: str
    data_dir: Path
    log: Path

    def request_of(self, job_id: int) -> dict:
        """The hints the server stored for job ``job_id`` (what the page sent)."""
        db = sqlite3.connect(f"file:{self.data_dir / 'starnav.sqlite'}?mode=ro", uri=True)
        try:
            (text,) = db.execute("SELECT request FROM jobs WHERE id = ?", (job_id,)).fetchone()
        finally:
            db.close()
        return json.loads(text)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def serve(tmp_path_factory):
    """Start ``starnav serve`` (extra options as arguments); every server stops at the end."""
    procs = []

    def start(*options: str) -> Server:
        tmp = tmp_path_factory.mktemp("serve")
        port = _free_port()
        log = tmp / "server.log"
        cmd = [sys.executable, "-m", "starnav.cli", "serve", "--port", str(port),
               "--data-dir", str(tmp / "data"), *options]  # fmt: skip
        with log.open("wb") as out:
            procs.append(subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT))
        url = f"http://127.0.0.1:{port}/"
        try:
            wait_ready(url, timeout_s=60.0)
        except OSError:
            pytest.fail(f"starnav serve did not start:\n{log.read_text()}")
        return Server(url, tmp / "data", log)

    try:
        yield start
    finally:
        for proc in procs:
            proc.terminate()
        for proc in procs:
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


@pytest.fixture(scope="module")
def server(serve) -> Server:
    return serve()


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    profile = tmp_path_factory.mktemp("chromium")
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--disable-background-networking", "--disable-component-update",
                "--disable-sync", "--no-first-run", f"--user-data-dir={profile}",
                "--window-size=1100,900"):  # fmt: skip
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(str(CHROMEDRIVER)), options=options)
    try:
        yield driver
    finally:
        driver.quit()


def _text(driver, css: str) -> str:
    return driver.find_element(By.CSS_SELECTOR, css).text


def _fill(driver, element_id: str, text: str) -> None:
    field = driver.find_element(By.ID, element_id)
    field.clear()
    field.send_keys(text)


def _field_size_hint(driver, lower: float, upper: float, units: str) -> None:
    driver.find_element(By.CSS_SELECTOR, "details summary").click()
    _fill(driver, "scale-lower", str(lower))
    _fill(driver, "scale-upper", str(upper))
    Select(driver.find_element(By.ID, "scale-units")).select_by_value(units)


def _solve(driver, server: Server, timeout_s: float, after: int | None = None) -> tuple[str, int]:
    """Click Solve and wait for the job to end (a job after job ``after``, the one the page
    showed before): its state and job number."""
    driver.find_element(By.ID, "submit").click()
    status = driver.find_element(By.ID, "status")
    try:
        # the new job's number first: until then the state shown may be the last job's
        WebDriverWait(driver, timeout_s, poll_frequency=0.25).until(
            lambda d: _text(d, "#job-id") not in ("", str(after))
        )
        WebDriverWait(driver, timeout_s, poll_frequency=0.25).until(
            lambda d: status.get_attribute("data-state") in ("success", "failure")
        )
    except TimeoutException:
        pytest.fail(
            f"no answer in {timeout_s:g} s: status {status.text!r}, form error "
            f"{_text(driver, '#form-error')!r}\nserver log:\n{server.log.read_text()[-3000:]}"
        )
    return status.get_attribute("data-state"), int(_text(driver, "#job-id"))


def _picture_loaded(driver, timeout_s: float = 10.0) -> bool:
    """Whether the annotated picture loaded (False when the server had none)."""
    img = driver.find_element(By.ID, "annotated")
    WebDriverWait(driver, timeout_s).until(
        lambda d: d.execute_script("return arguments[0].complete", img)
    )
    return driver.execute_script("return arguments[0].naturalWidth", img) > 0


def _get(url: str) -> tuple[int, bytes]:
    with urllib.request.urlopen(url, timeout=10) as resp:
        return resp.status, resp.read()


def _no_script_errors(driver) -> None:
    errors = [e for e in driver.get_log("browser") if e["source"] == "javascript"]
    assert not errors, errors


def _separation_arcsec(ra1, dec1, ra2, dec2) -> float:
    ra1, dec1, ra2, dec2 = map(math.radians, (ra1, dec1, ra2, dec2))
    cos = math.sin(dec1) * math.sin(dec2) + math.cos(dec1) * math.cos(dec2) * math.cos(ra1 - ra2)
    return math.degrees(math.acos(min(1.0, cos))) * 3600.0


def _sexagesimal_deg(text: str) -> float:
    """ "19h 05m 44.53s" (hours) or "+28° 56′ 35.8″" -> degrees."""
    parts = text.replace("h", " ").replace("m", " ").replace("s", " ")
    for mark in "°′″":
        parts = parts.replace(mark, " ")
    a, b, c = (float(p) for p in parts.split())
    value = abs(a) + b / 60.0 + c / 3600.0
    value = -value if text.startswith("-") else value
    return value * 15.0 if "h" in text else value


def _check_pointing(driver) -> dict:
    """The solution shown against the reference; the numbers read off the page."""
    ra = float(_text(driver, "#ra .deg").rstrip("°"))
    dec = float(_text(driver, "#dec .deg").rstrip("°"))
    roll = float(_text(driver, "#roll").split("°")[0])
    assert _sexagesimal_deg(_text(driver, "#ra .sexa")) == pytest.approx(ra, abs=5e-5)
    assert _sexagesimal_deg(_text(driver, "#dec .sexa")) == pytest.approx(dec, abs=5e-5)
    sep = _separation_arcsec(ra, dec, REFERENCE["ra_deg"], REFERENCE["dec_deg"])
    assert sep < BORESIGHT_TOL_ARCSEC, (ra, dec)
    droll = (roll - REFERENCE["roll_deg"] + 180.0) % 360.0 - 180.0
    assert abs(droll) < ROLL_TOL_DEG, roll
    assert "(1σ" in _text(driver, "#sigma-boresight")
    assert "(1σ)" in _text(driver, "#roll")
    rows = driver.find_elements(By.CSS_SELECTOR, "#stars tbody tr")
    n_matched = int(_text(driver, "#matched").split()[0])
    assert len(rows) == n_matched >= 10
    return {"ra_deg": ra, "dec_deg": dec, "rows": rows}


def _screenshot(driver, path: str) -> None:
    """The whole page, scaled to SCREENSHOT_SCALE, as a 256-colour PNG (the docs' copy is small)."""
    size = driver.execute_cdp_cmd("Page.getLayoutMetrics", {})["cssContentSize"]
    clip = {"x": 0, "y": 0, "width": size["width"], "height": size["height"],
            "scale": SCREENSHOT_SCALE}  # fmt: skip
    shot = driver.execute_cdp_cmd(
        "Page.captureScreenshot", {"format": "png", "captureBeyondViewport": True, "clip": clip}
    )
    picture = Image.open(io.BytesIO(base64.b64decode(shot["data"]))).convert("RGB")
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    picture.quantize(256).save(path, optimize=True)


@pytest.fixture(scope="module")
def image(tmp_path_factory) -> Path:
    return as_png(peer_image(LYRA), tmp_path_factory.mktemp("png"))


def test_image_solves_to_the_reference(server, browser, image):
    browser.get(server.url)
    browser.find_element(By.ID, "file").send_keys(str(image))
    _field_size_hint(browser, 10, 13, "degwidth")
    state, job = _solve(browser, server, FIRST_SOLVE_S)
    assert state == "success", _text(browser, "#reason")
    assert server.request_of(job) == {"parity": 2, "scale_units": "degwidth", "scale_type": "ul",
                                      "scale_lower": 10, "scale_upper": 13}  # fmt: skip
    shown = _check_pointing(browser)
    assert float(_text(browser, "#fov").split("°")[0]) == pytest.approx(
        REFERENCE["fov_deg"], rel=2e-3
    )
    assert _picture_loaded(browser)
    for link in ("dl-wcs", "dl-fits", "dl-json"):
        assert browser.find_element(By.ID, link).is_displayed()
    status, wcs = _get(browser.find_element(By.ID, "dl-wcs").get_attribute("href"))
    assert status == 200 and wcs.startswith(b"SIMPLE  =")
    status, fits = _get(browser.find_element(By.ID, "dl-fits").get_attribute("href"))
    assert status == 200 and fits.startswith(b"SIMPLE  =")
    status, body = _get(browser.find_element(By.ID, "dl-json").get_attribute("href"))
    assert status == 200 and json.loads(body)["ra_deg"] == pytest.approx(shown["ra_deg"], abs=1e-6)
    first = shown["rows"][0].find_elements(By.TAG_NAME, "td")
    assert int(first[0].text) > 0  # a HIP number
    _no_script_errors(browser)
    if os.environ.get("STARNAV_SCREENSHOT"):
        _screenshot(browser, os.environ["STARNAV_SCREENSHOT"])


def test_pasted_source_list_solves(server, browser, image):
    det = detect_image(read_image(image))
    fits_xy = det.xy + 0.5  # ours (top-left corner origin) -> FITS 1-based
    lines = [
        f"{x:.3f} {y:.3f}" if i % 2 else f"{x:.3f},{y:.3f}" for i, (x, y) in enumerate(fits_xy)
    ]
    browser.get(server.url)
    browser.find_element(By.ID, "mode-xy").click()
    _fill(browser, "xy", "\n".join(lines))
    _fill(browser, "width", str(det.width))
    _fill(browser, "height", str(det.height))
    _field_size_hint(browser, 38, 42, "arcsecperpix")
    _fill(browser, "center-ra", "286")
    _fill(browser, "center-dec", "29")
    _fill(browser, "radius", "5")
    Select(browser.find_element(By.ID, "parity")).select_by_value("1")
    state, job = _solve(browser, server, FIRST_SOLVE_S)
    assert state == "success", _text(browser, "#reason")
    sent = server.request_of(job)
    assert (sent["image_width"], sent["image_height"]) == (det.width, det.height)
    np.testing.assert_allclose(np.column_stack([sent["x"], sent["y"]]), fits_xy, atol=1e-3)
    hints = {k: v for k, v in sent.items() if k not in ("x", "y", "image_width", "image_height")}
    assert hints == {"parity": 1, "scale_units": "arcsecperpix", "scale_type": "ul",
                     "scale_lower": 38, "scale_upper": 42, "center_ra": 286, "center_dec": 29,
                     "radius": 5}  # fmt: skip
    _check_pointing(browser)
    assert not browser.find_element(By.ID, "dl-fits").is_displayed()  # no image: no .new
    assert _picture_loaded(browser)  # the sources drawn on a black frame
    _no_script_errors(browser)


def test_too_few_stars_fail_with_reason_and_picture(server, browser, tmp_path):
    rng = np.random.default_rng(7)
    yy, xx = np.mgrid[0:240, 0:320]
    pixels = rng.normal(1000.0, 30.0, (240, 320))
    for x, y in [(50, 60), (200, 100), (120, 180), (280, 40), (30, 200)]:
        pixels += 5000.0 * np.exp(-((xx - x) ** 2 + (yy - y) ** 2) / 4.0)
    path = tmp_path / "five_stars.png"
    Image.fromarray(pixels.clip(0, 65535).astype(np.uint16)).save(path)
    browser.get(server.url)
    browser.find_element(By.ID, "file").send_keys(str(path))
    _field_size_hint(browser, 10, 13, "degwidth")  # the tables the first test built
    state, _ = _solve(browser, server, SOLVE_S)
    assert state == "failure"
    assert _text(browser, "#reason")
    assert not browser.find_element(By.ID, "solution").is_displayed()
    assert _picture_loaded(browser)
    assert "not solved" in _text(browser, "#picture-caption")
    _no_script_errors(browser)


DROP_FILE = """
const [name, text] = arguments;
const files = new DataTransfer();
files.items.add(new File([text], name, {type: "text/plain"}));
const drop = document.getElementById("drop");
for (const type of ["dragenter", "drop"]) {
  drop.dispatchEvent(new DragEvent(type, {dataTransfer: files, bubbles: true, cancelable: true}));
}
"""


def test_dropped_non_image_fails_with_reason(server, browser):
    browser.get(server.url)
    browser.execute_script(DROP_FILE, "notes.txt", "these are not pixels\n")
    assert browser.execute_script("return document.getElementById('file').files[0].name") == (
        "notes.txt"
    )
    state, _ = _solve(browser, server, SOLVE_S)
    assert state == "failure"
    assert "not an image format" in _text(browser, "#reason")
    assert not _picture_loaded(browser)
    assert not browser.find_element(By.ID, "picture").is_displayed()
    _no_script_errors(browser)


def test_form_errors_are_shown_before_sending(server, browser):
    browser.get(server.url)
    browser.find_element(By.ID, "submit").click()
    assert "Choose an image" in _text(browser, "#form-error")
    browser.find_element(By.ID, "mode-xy").click()
    _fill(browser, "xy", "10 20\nten 30")
    _fill(browser, "width", "100")
    _fill(browser, "height", "100")
    browser.find_element(By.ID, "submit").click()
    assert "line 2" in _text(browser, "#form-error")
    assert not browser.find_element(By.ID, "progress").is_displayed()


def test_asks_for_the_key_of_a_server_with_one(serve, browser, tmp_path):
    keyed = serve("--api-key", API_KEY)
    path = tmp_path / "notes.txt"
    path.write_text("these are not pixels\n")
    browser.get(keyed.url)
    assert not browser.find_element(By.ID, "apikey").is_displayed()
    browser.find_element(By.ID, "file").send_keys(str(path))
    browser.find_element(By.ID, "submit").click()
    WebDriverWait(browser, 10).until(lambda d: d.find_element(By.ID, "apikey").is_displayed())
    assert "needs an API key" in _text(browser, "#form-error")
    _fill(browser, "apikey", "wrong")
    browser.find_element(By.ID, "submit").click()
    WebDriverWait(browser, 10).until(lambda d: "refused" in _text(d, "#form-error"))
    _fill(browser, "apikey", API_KEY)
    state, public = _solve(browser, keyed, SOLVE_S)
    assert state == "failure" and "not an image format" in _text(browser, "#reason")
    assert _get(f"{keyed.url}api/jobs/{public}")[0] == 200
    # a private job: the page reads its answer (api/login's cookie), nobody else can
    browser.find_element(By.ID, "private").click()
    browser.find_element(By.ID, "file").send_keys(str(path))
    state, private = _solve(browser, keyed, SOLVE_S, after=public)
    assert state == "failure" and "not an image format" in _text(browser, "#reason")
    assert keyed.request_of(private)["publicly_visible"] == "n"
    with pytest.raises(urllib.error.HTTPError) as refused:
        _get(f"{keyed.url}api/jobs/{private}/starnav")
    assert refused.value.code == 404
