"""Nothing outside --data-dir: a real ``starnav serve`` process, its HOME and TMPDIR fresh
empty folders (XDG_* unset), runs an image that solves, a source list, a bad file, an odd
hint and an image of an odd epoch (new tables), is stopped with SIGTERM while solving and
SIGKILLed (with its workers) while solving; then HOME and TMPDIR are still empty, the shared
table cache it read is unchanged, no table was written past the cache limit, and each start
cleaned what the last run left (DATA/tmp, a job whose upload was never stored). And the
parts: a data dir in use is refused; the cleaning itself."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
from astropy.io import fits

from cli_helpers import run_cli
from service_helpers import (
    Server,
    api,
    login,
    source_list,
    upload_image,
    upload_list,
    wait_done,
)
from shared_data import CYGNUS, LYRA, USER_CACHE_DIR, peer_image
from starnav.errors import StarnavError
from starnav.runtime.caching import kernel_cache_dir, stored_bytes
from starnav.service.files import (
    JOB_TMP_PREFIX,
    Leftovers,
    clean_leftovers,
    link_tables,
    link_tree,
    lock_data_dir,
)
from starnav.service.store import UNSTORED, JobStore

pytestmark = pytest.mark.service

# the odd epoch's two tables (8 and 17 MB): one is written, the next would pass the limit
LIMIT_MB = 20

XDG = ("XDG_CACHE_HOME", "XDG_CONFIG_HOME", "XDG_DATA_HOME", "XDG_STATE_HOME",
       "XDG_RUNTIME_DIR", "MPLCONFIGDIR", "ASTROPY_CACHE_DIR", "ASTROPY_CONFIG_DIR")  # fmt: skip


def tree(folder: Path) -> dict[str, str]:
    """Every entry under ``folder`` (relative path -> link target, "" for a file or folder)."""
    out = {}
    for path in sorted(folder.rglob("*")):
        out[str(path.relative_to(folder))] = os.readlink(path) if path.is_symlink() else ""
    return out


def shared_cache(folder: Path) -> tuple[Path, Path]:
    """A cache standing for the user's, its files links to the user's tables and machine code
    (so that a write to it shows, and nothing is built): (tables, numba cache)."""
    user = Path(USER_CACHE_DIR or Path.home() / ".cache" / "starnav")
    tables, numba = folder / "tables", folder / "numba"
    tables.mkdir(parents=True)
    link_tables(user, tables)
    link_tree(kernel_cache_dir(os.environ.get("NUMBA_CACHE_DIR", "")), kernel_cache_dir(str(numba)))
    return tables, numba


def fits_of_epoch(path: Path, date_obs: str) -> bytes:
    """The Lyra frame as a 16-bit FITS image observed at ``date_obs``: the catalog taken to
    that date by its proper motion needs tables no cache holds (each new year, new tables)."""
    from starnav.detect import read_image

    pixels = np.asarray(read_image(path), dtype=float)
    scaled = np.clip(pixels / pixels.max() * 65535.0, 0, 65535).astype(np.uint16)
    hdu = fits.PrimaryHDU(scaled)
    hdu.header["DATE-OBS"] = date_obs
    return _bytes(hdu)


def _bytes(hdu) -> bytes:
    import io

    buf = io.BytesIO()
    hdu.writeto(buf)
    return buf.getvalue()


def wait_for(test, what: str, timeout_s: float = 60.0, poll_s: float = 0.05):
    deadline = time.monotonic() + timeout_s
    while not (found := test()):
        assert time.monotonic() < deadline, f"no {what} after {timeout_s:g} s"
        time.sleep(poll_s)
    return found


def job_tmp(data: Path) -> list[Path]:
    tmp = data / "tmp"
    return sorted(tmp.glob(JOB_TMP_PREFIX + "*")) if tmp.is_dir() else []


def sigterm(server: Server) -> None:
    server.proc.send_signal(signal.SIGTERM)
    server.proc.wait(60)
    server.proc = None


@pytest.mark.slow
def test_nothing_is_written_outside_the_data_dir(tmp_path):
    home, tmp, data = tmp_path / "home", tmp_path / "tmp", tmp_path / "data"
    home.mkdir()
    tmp.mkdir()
    tables, numba = shared_cache(tmp_path / "shared")
    shared_before = tree(tmp_path / "shared")
    env = {"HOME": str(home), "TMPDIR": str(tmp), "STARNAV_CACHE_DIR": str(tables),
           "NUMBA_CACHE_DIR": str(numba), **dict.fromkeys(XDG)}  # fmt: skip
    server = Server(data, workers=2, options=("--cache-limit-mb", str(LIMIT_MB)), env=env).start()
    lyra, cygnus = peer_image(LYRA).read_bytes(), peer_image(CYGNUS).read_bytes()
    try:
        session = login(server.url)
        x, y = source_list(LYRA)
        wide = {"scale_units": "degwidth", "scale_type": "ul", "scale_lower": 61.0,
                "scale_upper": 67.0}  # fmt: skip
        lyra_fov = dict(wide, scale_lower=11.0, scale_upper=12.0)
        date = "2150-04-10T21:00:00"  # a year no cache holds tables of
        jobs = {
            "image": upload_image(server.url, session, LYRA, lyra),
            "list": upload_list(server.url, session, x, y, 1024, 768),
            "bad file": upload_image(server.url, session, "x.png", b"not an image\n" * 50),
            "odd hint": upload_list(server.url, session, x, y, 1024, 768, wide),
            "odd epoch": upload_image(server.url, session, "old.fits",
                                      fits_of_epoch(peer_image(LYRA), date), lyra_fov),
        }  # fmt: skip
        status = {kind: wait_done(server.url, job_id, 300.0) for kind, job_id in jobs.items()}
        assert status["image"] == status["list"] == "success", status
        assert status["bad file"] == "failure"
        assert api(server.url, f"jobs/{jobs['bad file']}/starnav")["reason"].startswith("error")

        # SIGTERM while a worker solves an image: its input is in DATA/tmp, and goes
        solving = upload_image(server.url, session, CYGNUS, cygnus)
        wait_for(lambda: job_tmp(data), "job folder in DATA/tmp")
        sigterm(server)
        assert list((data / "tmp").iterdir()) == []

        # a job made but its upload never stored (a server stopped between the two)
        store = JobStore(data)
        unstored = store.add_job("image", "half.png", {})
        (store.job_dir(unstored) / "input.png").write_bytes(lyra[:1000])
        store.close()

        server.start()
        assert f"job(s) {unstored} without their upload" in server.log()
        assert api(server.url, f"jobs/{unstored}/starnav")["reason"] == UNSTORED
        assert not store.job_dir(unstored).exists()
        assert api(server.url, f"jobs/{solving}/starnav")["reason"].startswith("interrupted")

        # SIGKILL of the server and its workers while solving: the next start cleans DATA/tmp
        session = login(server.url)
        upload_image(server.url, session, CYGNUS, cygnus)
        wait_for(lambda: job_tmp(data), "job folder in DATA/tmp")
        left = sorted(p.name for p in (data / "tmp").iterdir())
        server.kill()
        server.start()
        assert "temporary file(s) or folder(s)" in server.log().split("starnav serve: ")[-1]
        assert not set(left) & {p.name for p in (data / "tmp").iterdir()}
        sigterm(server)
    finally:
        server.kill()
    assert tree(home) == {}
    assert tree(tmp) == {}
    assert tree(tmp_path / "shared") == shared_before
    assert 0 < stored_bytes(data / "cache") <= LIMIT_MB * 1e6
    assert list((data / "tmp").iterdir()) == []


def test_a_second_server_on_a_data_dir_is_refused_and_leftovers_are_cleaned(tmp_path):
    fd, pid = lock_data_dir(tmp_path), os.getpid()
    with pytest.raises(StarnavError, match=f"in use by another starnav serve .process {pid}"):
        lock_data_dir(tmp_path)
    store = JobStore(tmp_path)
    stored, unstored = store.add_job("image", "a.png", {}), store.add_job("image", "b.png", {})
    store.set_input(stored, "input.png")
    listed = store.add_job("xy", "json-xy", {"x": [1.0], "y": [2.0]})
    store.close()
    (tmp_path / "tmp" / "pymp-x").mkdir(parents=True)
    (tmp_path / "tmp" / f"{JOB_TMP_PREFIX}y").mkdir()
    (tmp_path / "tmp" / f"{JOB_TMP_PREFIX}y" / "input.png").write_bytes(b"\x89PNG")
    cleaned = clean_leftovers(tmp_path)
    assert cleaned == Leftovers(2, (unstored,))
    assert str(cleaned) == (f"cleaned what the last run left: 2 temporary file(s) or folder(s) "
                            f"and job(s) {unstored} without their upload")  # fmt: skip
    assert list((tmp_path / "tmp").iterdir()) == []
    store = JobStore(tmp_path)
    assert [store.get(j).status for j in (stored, unstored, listed)] == ["queued", "failure",
                                                                         "queued"]  # fmt: skip
    assert store.get(unstored).reason == UNSTORED
    assert store.job_dir(stored).is_dir() and not store.job_dir(unstored).exists()
    store.close()
    assert str(clean_leftovers(tmp_path)) == ""
    os.close(fd)  # the lock goes with it
    os.close(lock_data_dir(tmp_path))


def test_serve_refuses_a_data_dir_in_use_and_a_negative_cache_limit(capsys, tmp_path):
    fd = lock_data_dir(tmp_path)
    code, out, err = run_cli(capsys, "serve", "--data-dir", str(tmp_path), "--port", "1")
    assert code == 2 and out == ""
    assert err.count("\n") == 1 and "is in use by another starnav serve" in err
    os.close(fd)
    code, _, err = run_cli(capsys, "serve", "--data-dir", str(tmp_path), "--cache-limit-mb", "-1")
    assert code == 2 and "--cache-limit-mb must be 0 or more, got -1" in err
