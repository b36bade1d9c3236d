"""The order the suite runs in under pytest-xdist (tests/conftest.py balanced_order): worksteal hands each of the
two workers one half of the list, so each half must start with its longest modules and the halves must split
where the list does."""
from __future__ import annotations

from dataclasses import dataclass

from conftest import _recorded_seconds, balanced_order


@dataclass
class Item:
    nodeid: str


def _items(spec):
    return [Item(f"{m}::t{i}") for m, n in spec for i in range(n)]


def test_the_two_heaviest_modules_start_the_two_halves_whole():
    items = _items([("light.py", 6), ("heavy.py", 2), ("medium.py", 3), ("tiny.py", 1)])
    seconds = {"heavy.py::t0": 20.0, "heavy.py::t1": 10.0, "medium.py::t0": 12.0, "light.py::t0": 3.0}
    order = balanced_order(items, seconds, default=0.1)
    assert sorted(i.nodeid for i in order) == sorted(i.nodeid for i in items)
    half = len(items) // 2
    first, second = [i.nodeid for i in order[:half]], [i.nodeid for i in order[half:]]
    assert first[:2] == ["heavy.py::t0", "heavy.py::t1"]
    assert second[:3] == ["medium.py::t0", "medium.py::t1", "medium.py::t2"]
    # the counts evened with the lightest modules' tests (light.py split), each half keeping their order
    assert {n[:5] for n in first} == {"heavy", "light", "tiny."}
    for half_ in (first, second):
        light = [int(n.split("::t")[1]) for n in half_ if n.startswith("light.py")]
        assert light == sorted(light)


def test_a_half_short_of_tests_takes_the_other_halfs_lightest():
    items = _items([("a.py", 1), ("b.py", 1), ("c.py", 8)])
    order = [i.nodeid for i in balanced_order(items, {"a.py::t0": 30.0, "b.py::t0": 29.0}, default=0.1)]
    assert order[0] == "a.py::t0" and order[len(items) // 2] == "b.py::t0"


def test_the_recorded_seconds_are_read():
    seconds = _recorded_seconds()
    assert seconds and all(s > 0 for s in seconds.values())
    assert all("::" in node and node.startswith("tests/test_") for node in seconds)
