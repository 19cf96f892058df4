"""Finds dfrl's packages and data files; everything else is in pyproject.toml.

The installed package ``dfrl`` has the project's top-level folders as subpackages
(``dfrl.robots`` is ``robots/``), a mapping pyproject.toml cannot express with its package
finder. Here every folder under those roots is a package (setuptools treats a folder of data
files as one) and every file with a data suffix is data of its folder, so a new module, subpackage,
Prolog file or arena is shipped without being listed (tests/packaging checks the wheel against
the files git tracks). The platform's foreign libraries ship as C sources: they are compiled on
first use into a per-user cache (platform_pl/native_library.pl says why).
"""

from __future__ import annotations

from pathlib import Path

from setuptools import setup

#: The project's folders that become ``dfrl.<folder>``.
ROOTS = ("platform_pl", "pybridge", "robots", "arenas", "experiments")
#: Suffixes of the files shipped beside the modules (never compiled objects or caches).
DATA_SUFFIXES = {".pl", ".json", ".md", ".c", ".sh", ".html", ".js", ".css", ".npy", ".typed"}

HERE = Path(__file__).resolve().parent


def _packages() -> dict[str, Path]:
    """Every folder under the roots, as setuptools wants data folders to be packages too
    (namespace packages where there is no ``__init__.py``)."""
    found = {"dfrl": HERE / "dfrl"}
    for root in ROOTS:
        for folder in [HERE / root, *sorted((HERE / root).rglob("*"))]:
            rel = folder.relative_to(HERE).parts
            if folder.is_dir() and not any(p == "__pycache__" or p.startswith(".") for p in rel):
                found[".".join(("dfrl", *rel))] = folder
    return found


def _package_data(packages: dict[str, Path]) -> dict[str, list[str]]:
    return {
        name: sorted(p.name for p in folder.iterdir() if p.is_file() and p.suffix in DATA_SUFFIXES)
        for name, folder in packages.items()
    }


PACKAGES = _packages()

setup(
    packages=sorted(PACKAGES),
    package_dir={name: folder.relative_to(HERE).as_posix() for name, folder in PACKAGES.items()},
    package_data=_package_data(PACKAGES),
)
