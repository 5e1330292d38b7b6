"""The public surface of :mod:`reference`: one spelling per name, ``__all__`` that
tells the truth, no function that shadows a module, and every docstring
example run as a doctest."""

from __future__ import annotations

import doctest
import importlib
import inspect
import pkgutil
import types

import pytest

import reference

PRIVATE_MODULES = sorted(
    info.name for info in pkgutil.iter_modules(reference.__path__) if info.name.startswith("_")
)


def test_every_module_is_private():
    public = [info.name for info in pkgutil.iter_modules(reference.__path__)
              if not info.name.startswith("_")]  # fmt: skip
    assert public == [], f"public modules {public}: implementation belongs in _modules"
    assert {"_geometry", "_nodes", "_weights", "_barycentric", "_lebesgue", "_bezier",
            "_splines", "_delaunay", "_plotting", "_data",
            "_validation"} <= set(PRIVATE_MODULES)  # fmt: skip


def test_package_all_matches_what_it_exports():
    names = reference.__all__
    assert len(names) == len(set(names)), "a name is listed twice in __all__"
    for name in names:
        assert hasattr(reference, name), f"reference.__all__ lists {name!r}, which is missing"
    public = {n for n, v in vars(reference).items()
              if not n.startswith("_") and not isinstance(v, types.ModuleType)}  # fmt: skip
    assert public == set(names)


def test_package_all_is_the_union_of_the_modules_all():
    exported = set()
    for name in PRIVATE_MODULES:
        module = importlib.import_module(f"reference.{name}")
        if name in ("_validation", "_predicates"):
            continue  # internal helpers, not re-exported
        exported |= set(module.__all__)
    assert exported == set(reference.__all__)


@pytest.mark.parametrize("name", PRIVATE_MODULES)
def test_module_all_matches_its_definitions(name):
    module = importlib.import_module(f"reference.{name}")
    assert hasattr(module, "__all__"), f"reference.{name} has no __all__"
    defined = {
        n for n, v in vars(module).items()
        if not n.startswith("_")
        and not isinstance(v, types.ModuleType)
        and (getattr(v, "__module__", None) == module.__name__ or n.isupper())
        and (callable(v) or n.isupper())
        and n not in ("annotations",)
    }  # fmt: skip
    assert set(module.__all__) == defined, (
        f"reference.{name}.__all__ = {sorted(module.__all__)}, defines {sorted(defined)}"
    )


def test_no_public_name_shadows_a_module():
    for name in reference.__all__:
        value = getattr(reference, name)
        assert not isinstance(value, types.ModuleType)
    # the functions named like their subject are functions, and the modules
    # behind them stay reachable under their own private names
    assert inspect.isfunction(reference.bezier) and inspect.isfunction(reference.delaunay)
    assert importlib.import_module("reference._bezier").bezier is reference.bezier
    assert importlib.import_module("reference._delaunay").delaunay is reference.delaunay


def test_every_public_name_is_documented_with_an_example():
    for name in reference.__all__:
        value = getattr(reference, name)
        if not callable(value):
            continue
        doc = inspect.getdoc(value) or ""
        if inspect.isclass(value):
            # a class documents its attributes; one built by a factory says which
            assert "Attributes" in doc, f"reference.{name} has no Attributes section"
            assert "Examples" in doc or "Build it with" in doc, f"reference.{name}: no example"
            continue
        sections = ["Returns", "Examples"]
        if inspect.signature(value).parameters:
            sections.append("Parameters")
        for section in sections:
            assert section in doc, f"reference.{name} has no {section} section"


def test_public_predicates_are_vectorised_and_public():
    assert reference.orient2d_many([0, 0], [1, 0], [[0, 1], [0, -1]]).tolist() == [1, -1]
    assert reference.incircle_many([1, 0], [0, 1], [-1, 0], [[0, 0], [5, 5]]).tolist() == [1, -1]


@pytest.mark.parametrize("name", ["__init__"] + PRIVATE_MODULES)
def test_doctests(name):
    module = reference if name == "__init__" else importlib.import_module(f"reference.{name}")
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0


def test_importing_the_package_loads_neither_matplotlib_nor_scipy():
    """A grader imports ``reference`` for its checks at every start: the figures'
    matplotlib and the scipy modules a few functions use are loaded on first use."""
    import subprocess
    import sys

    code = ("import sys, reference\n"
            "heavy = ['matplotlib', 'scipy.linalg', 'scipy.special', 'scipy.spatial']\n"
            "print([m for m in heavy if m in sys.modules])\n"
            "from reference import plot_car\n"
            "print('matplotlib' in sys.modules, 'plot_car' in dir(reference))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          timeout=120, check=True)
    assert done.stdout.split("\n")[:2] == ["[]", "True True"], done.stdout + done.stderr
