"""The options of an identification algorithm that can be set by name (from the command line:
``--algorithm-option NAME=VALUE``), checked alike for every algorithm.

An algorithm class declares them in its ``OPTIONS``: (name, allowed) pairs (or a mapping),
``allowed`` being the values allowed (a tuple) or their type (``int``, ``float`` or ``str``).
A class without ``OPTIONS`` takes none by name (its keyword arguments remain open to
``solve(..., algorithm_options=...)``).
"""

from __future__ import annotations

from collections.abc import Mapping
from importlib import import_module

from starnav.errors import StarnavError, shown
from starnav.identify import ALGORITHMS

_KINDS = {int: "a whole number", float: "a number", str: "text"}


def declared_options(algorithm: str) -> dict[str, tuple | type]:
    """The options ``algorithm`` (a name of ``ALGORITHMS``) declares: name -> allowed values
    or type."""
    if algorithm not in ALGORITHMS:
        raise StarnavError(f"unknown algorithm {algorithm!r}; known: {', '.join(ALGORITHMS)}")
    module, cls = ALGORITHMS[algorithm]
    return dict(getattr(getattr(import_module(module), cls), "OPTIONS", {}))


def _check_value(algorithm: str, name: str, allowed: tuple | type, value: object) -> None:
    if isinstance(allowed, tuple):
        if value not in allowed:
            raise StarnavError(
                f"algorithm option {name} of {algorithm} must be one of "
                f"{', '.join(map(str, allowed))}, got {shown(value)}"
            )
        return
    fits = isinstance(value, allowed) and not isinstance(value, bool)
    if allowed is float:
        fits = isinstance(value, int | float) and not isinstance(value, bool)
    if not fits:
        kind = _KINDS.get(allowed, allowed.__name__)
        raise StarnavError(
            f"algorithm option {name} of {algorithm} must be {kind}, got {shown(value)}"
        )


def check_algorithm_options(
    algorithm: str,
    options: Mapping[str, object],
    defaults: Mapping[str, object] | None = None,
) -> dict[str, object]:
    """``options`` checked against what ``algorithm`` declares (``StarnavError`` naming the
    first option it does not take or a value it does not allow), completed by those of
    ``defaults`` that it declares and ``options`` leaves out (a default the algorithm does
    not declare is dropped: ``defaults`` may serve several algorithms)."""
    declared = declared_options(algorithm)
    for name in options:
        if name not in declared:
            known = f"its options: {', '.join(declared)}" if declared else "it takes none"
            raise StarnavError(f"algorithm {algorithm} has no option {name!r} ({known})")
    out = {k: v for k, v in (defaults or {}).items() if k in declared and k not in options}
    out.update(options)
    for name, value in out.items():
        _check_value(algorithm, name, declared[name], value)
    return out


def describe_options(options: Mapping[str, object]) -> str:
    """Options in a few words for a report: a text value by itself ("optimized"), anything
    else as name=value; "" for none."""
    return ", ".join(v if isinstance(v, str) else f"{k}={v}" for k, v in options.items())
