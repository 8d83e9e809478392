"""Package discovery for the three source folders; everything else is in pyproject.toml.

``[tool.setuptools.package-dir]`` maps each import name to its folder (``trackingbox`` to
``pyside/trackingbox``, ``trackingbox.codegen`` to ``codegen``, ``trackingbox.modelica`` to
``modelica``). ``[tool.setuptools.packages.find]`` names a package after its path from
``where``, so it cannot put ``codegen/`` under ``trackingbox``: the packages are found here,
under each mapped folder, instead of being listed by hand (a hand-kept list left
``trackingbox.report`` and ``trackingbox.testing`` out of the wheel). Folders without an
``__init__.py`` (the Modelica library's sub-packages, the diagnose effects) are found as
namespace packages, so the data files in them belong to a package and setuptools has
nothing to warn about.
"""
from __future__ import annotations

import sys
from pathlib import Path

from setuptools import find_namespace_packages, setup

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

HERE = Path(__file__).resolve().parent


def found_packages() -> list[str]:
    """Every package under each folder that ``package-dir`` maps, named under its import name."""
    config = tomllib.loads((HERE / "pyproject.toml").read_text(encoding="utf-8"))
    package_dir: dict[str, str] = config["tool"]["setuptools"]["package-dir"]
    packages = set(package_dir)
    for name, folder in package_dir.items():
        packages.update(f"{name}.{sub}" for sub in find_namespace_packages(
            where=str(HERE / folder), exclude=["*__pycache__*"]))
    return sorted(packages)


setup(packages=found_packages())
