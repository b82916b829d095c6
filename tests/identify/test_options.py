"""Algorithm options set by name (``--algorithm-option``): declared by the class, checked alike."""

import pytest

from starnav.errors import StarnavError
from starnav.evaluate import EvalConfig
from starnav.evaluate.report import describe
from starnav.identify import ALGORITHMS
from starnav.identify.options import check_algorithm_options, declared_options, describe_options


def test_triangle_declares_its_selection_and_the_others_nothing():
    assert declared_options("triangle") == {"selection": ("optimized", "brightest")}
    assert all(declared_options(name) == {} for name in ALGORITHMS if name != "triangle")
    with pytest.raises(StarnavError, match="unknown algorithm"):
        declared_options("nope")


def test_options_are_checked_and_completed_by_the_declared_defaults():
    defaults = {"selection": "optimized"}
    assert check_algorithm_options("triangle", {}, defaults) == defaults
    assert check_algorithm_options("triangle", {"selection": "brightest"}, defaults) == {
        "selection": "brightest"
    }
    assert check_algorithm_options("pyramid", {}, defaults) == {}  # not one of its options


@pytest.mark.parametrize(
    "algorithm,options,needle",
    [
        (
            "pyramid",
            {"selection": "brightest"},
            "pyramid has no option 'selection' (it takes none)",
        ),
        ("triangle", {"size": 3}, "no option 'size' (its options: selection)"),
        ("triangle", {"selection": "dimmest"}, "must be one of optimized, brightest"),
    ],
)
def test_a_bad_option_is_named(algorithm, options, needle):
    with pytest.raises(StarnavError, match="algorithm") as info:
        check_algorithm_options(algorithm, options)
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_report_names_the_options_of_any_algorithm():
    assert describe_options({"selection": "optimized", "max_triangles": 2}) == (
        "optimized, max_triangles=2"
    )
    line = describe(EvalConfig(algorithm="triangle", algorithm_options=(("selection", "x"),)), "s")
    assert "; triangle (x), sigma_px" in line
    assert "; pyramid, sigma_px" in describe(EvalConfig(), "s")


def test_typed_options(monkeypatch):
    from starnav.identify.triangle import SELECTIONS, Triangle

    declared = {"selection": SELECTIONS, "max_triangles": int, "min_side_px": float}
    monkeypatch.setattr(Triangle, "OPTIONS", declared)
    good = {"max_triangles": 2, "min_side_px": 3}
    assert check_algorithm_options("triangle", good) == good
    for bad, needle in (
        ({"max_triangles": 2.5}, "a whole number"),
        ({"min_side_px": "x"}, "a number"),
    ):
        with pytest.raises(StarnavError, match=needle):
            check_algorithm_options("triangle", bad)
