"""The process-wide caches in one registry: what a process keeps in memory once made (the
catalogs loaded, pair databases, pattern tables, FOV-search bands, prepared solvers).

Each cache is a ``ProcessCache`` made here by name; ``caches()`` lists them with their sizes and
``clear_caches()`` empties them all (a long-running service, or a test that must start cold).
A cache with ``max_items`` is emptied when it would grow past it: its entries are cheap to make
again next to the memory they hold (a prepared solver keeps a pair database alive).
"""

from __future__ import annotations

from typing import Any

_REGISTRY: dict[str, ProcessCache] = {}


class ProcessCache(dict):
    """A named in-memory cache of this process (a ``dict``), emptied when it would hold more
    than ``max_items`` entries (None: no limit)."""

    def __init__(self, name: str, max_items: int | None = None) -> None:
        super().__init__()
        self.name = name
        self.max_items = max_items

    def __setitem__(self, key: Any, value: Any) -> None:
        if self.max_items is not None and key not in self and len(self) >= self.max_items:
            self.clear()
        super().__setitem__(key, value)

    def __repr__(self) -> str:
        return f"ProcessCache({self.name!r}, {len(self)} entries, max_items={self.max_items})"


def process_cache(name: str, max_items: int | None = None) -> ProcessCache:
    """The process cache called ``name``, made on first call (one per name)."""
    cache = _REGISTRY.get(name)
    if cache is None:
        cache = _REGISTRY[name] = ProcessCache(name, max_items)
    return cache


def caches() -> dict[str, int]:
    """Every registered cache's name and number of entries."""
    return {name: len(cache) for name, cache in _REGISTRY.items()}


def clear_caches() -> None:
    """Empty every registered cache (the next solve loads and prepares again)."""
    for cache in _REGISTRY.values():
        cache.clear()
