"""Where the shipped parameter files (``models/``) and recordings (``datasets/``) are.

In a source checkout (run from the tree, or ``pip install -e .``) they are the project's
top-level folders ``models/`` and ``datasets/``. An installed wheel carries them as package
data, ``hframe_id/_data/models`` and ``hframe_id/_data/datasets`` (copied there by the build
step in setup.py), found through ``importlib.resources``. No other module knows the layout.

The folders are ``pathlib.Path`` objects: pip installs the package unzipped, and the readers
(parameter files, MCAP) take paths.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from hframe_id.errors import HframeIdError

#: The checkout: the folder holding this package, pyproject.toml, models/ and datasets/.
_CHECKOUT = Path(__file__).resolve().parents[1]


class ResourceNotFoundError(HframeIdError, FileNotFoundError):
    """A shipped parameter file or recording is not where the package keeps them."""


def _package_data() -> Path | None:
    """``hframe_id/_data`` of an installed wheel, or None (a checkout)."""
    data = resources.files(__package__) / "_data"
    return data if isinstance(data, Path) and data.is_dir() else None


def project_root() -> Path | None:
    """The source checkout this package runs from, or None when it is installed from a wheel
    (then there is no project folder: no git commit, no paths relative to it)."""
    if _package_data() is not None:
        return None
    if (_CHECKOUT / "pyproject.toml").is_file() and (_CHECKOUT / "models").is_dir():
        return _CHECKOUT
    return None


def _folder(name: str) -> Path:
    root = project_root()
    if root is not None:
        return root / name
    # installed: the package data (or where it should be, for the error messages)
    return Path(str(resources.files(__package__))) / "_data" / name


def models_dir() -> Path:
    """The folder of the thesis's parameter files (``models/*.yaml``). Never raises, so that
    modules can take it at import; :func:`model_file` says when a file is missing."""
    return _folder("models")


def datasets_dir() -> Path:
    """The folder of the shipped recordings, truth files and manifests (``datasets/``)."""
    return _folder("datasets")


def _file(folder: Path, name: str, what: str) -> Path:
    path = folder / name
    if not path.is_file():
        where = "the checkout" if project_root() is not None else "the installed package"
        shipped = sorted(p.name for p in folder.glob("*.yaml" if what == "model" else "*.mcap"))
        hint = f"; shipped: {', '.join(shipped)}" if shipped else ""
        raise ResourceNotFoundError(
            f"no shipped {what} file {name!r}: looked for {path} (in {where}){hint}"
        )
    return path


def model_file(name: str) -> Path:
    """A shipped parameter file by name, e.g. ``model_file("hframe-8-table4.2.yaml")``."""
    return _file(models_dir(), name, "model")


def dataset_file(name: str) -> Path:
    """A shipped dataset file by its path inside ``datasets/``, e.g. ``"4V_xmotion.mcap"``,
    ``"truth/hframe-8-rig.yaml"`` or ``"realistic/manifest.yaml"``."""
    return _file(datasets_dir(), name, "dataset")


def portable_path(path: Path | str) -> str:
    """A file's path as provenance records it, the same on every machine where possible:
    relative to the checkout when inside it (``datasets/4V_xmotion.mcap``); a file shipped in
    an installed package by the same name (``datasets/...``, ``models/...``); otherwise
    absolute (never relative to the working directory)."""
    absolute = Path(path).resolve()
    root = project_root()
    bases = {"": root} if root is not None else {"models": models_dir(), "datasets": datasets_dir()}
    for prefix, base in bases.items():
        try:
            return (Path(prefix) / absolute.relative_to(base.resolve())).as_posix()
        except ValueError:
            continue
    return str(absolute)
