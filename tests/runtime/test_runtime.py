"""The runtime home: process-wide caches in one registry, worker processes started one way."""

import ast
from pathlib import Path

import starnav
from starnav.runtime import caches, pools
from starnav.runtime.caches import ProcessCache, process_cache

SRC = Path(starnav.__file__).resolve().parent
WORKER_STATE = {"_WORKER"}  # a worker process's own state, set by its pool's initializer


def test_a_cache_is_one_per_name_and_empties_when_full():
    a = process_cache("test: small", max_items=2)
    assert process_cache("test: small") is a and isinstance(a, ProcessCache)
    a["x"], a["y"] = 1, 2
    a["x"] = 3  # replacing an entry is not growing
    assert dict(a) == {"x": 3, "y": 2}
    a["z"] = 4
    assert dict(a) == {"z": 4}
    assert caches.caches()["test: small"] == 1
    caches.clear_caches()
    assert len(a) == 0


def test_the_solver_caches_are_registered_and_filled_by_a_solve():
    from shared_data import CONTEST, shared_file
    from starnav.starlist import read_star_csv

    xy = read_star_csv(shared_file(CONTEST / "images" / "xingtu01.csv")).xy
    starnav.solve_stars(xy, width=512, fov_deg=12.0, catalog=shared_file(CONTEST / "catalog.csv"))
    sizes = caches.caches()
    assert sizes["pair databases"] >= 1 and sizes["prepared solvers"] >= 1
    assert {"Hipparcos catalogs", "4-star pattern tables", "FOV-search bands"} <= set(sizes)


def test_no_module_keeps_a_cache_of_its_own():
    """A module-level ``_NAME = {}`` / ``set()`` outside the runtime is a cache the registry
    does not know: it cannot be listed or cleared."""
    found = []
    for path in sorted(SRC.rglob("*.py")):
        if path.parent.name == "runtime":
            continue
        for node in ast.parse(path.read_text()).body:
            target = value = None
            if isinstance(node, ast.Assign) and len(node.targets) == 1:
                target, value = node.targets[0], node.value
            elif isinstance(node, ast.AnnAssign):
                target, value = node.target, node.value
            name = getattr(target, "id", "")
            if name.startswith("_") and name not in WORKER_STATE:
                empty_literal = isinstance(value, ast.Dict) and not value.keys
                empty_call = (
                    isinstance(value, ast.Call)
                    and getattr(value.func, "id", "") in ("dict", "set")
                    and not value.args
                )
                if empty_literal or empty_call:
                    found.append(f"{path.relative_to(SRC)}: {name}")
    assert not found


def test_worker_processes_are_started_in_one_place():
    """Only runtime/pools.py makes a process pool or picks a start method."""
    makers = []
    for path in sorted(SRC.rglob("*.py")):
        if path == SRC / "runtime" / "pools.py":
            continue
        text = path.read_text()
        if "ProcessPoolExecutor(" in text or "get_context(" in text:
            makers.append(str(path.relative_to(SRC)))
    assert not makers
    with pools.process_pool(2, start="spawn") as pool:
        assert sorted(pool.map(abs, [-1, -2, 3])) == [1, 2, 3]
    assert pools.worker_count(3) == 3 and pools.worker_count(None) >= 1
