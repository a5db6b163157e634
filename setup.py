"""Build step: ship the top-level ``models/`` and ``datasets/`` inside the package.

All metadata is in pyproject.toml; this file only adds the parameter files and recordings to
the wheel as ``hframe_id/_data/models`` and ``hframe_id/_data/datasets``, where
``hframe_id.resources`` finds them through ``importlib.resources``. The folders stay at the top
of the project (its fixed layout), so they cannot be ordinary package data; ``build_py`` copies
them instead, and names them as its source files so that an sdist carries them too. An
editable install copies nothing: ``hframe_id.resources`` reads the folders in the checkout.
"""

from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
#: Top-level folder -> the files shipped from it (glob patterns, relative to the folder).
SHIPPED = {
    "models": ("*.yaml", "*.py"),
    "datasets": ("**/*.mcap", "**/*.yaml", "**/README*"),
}
TARGET = Path("hframe_id", "_data")


def shipped_files() -> list[Path]:
    """Every shipped file, relative to the project root, sorted."""
    files = set()
    for folder, patterns in SHIPPED.items():
        for pattern in patterns:
            files.update(p.relative_to(ROOT) for p in (ROOT / folder).glob(pattern) if p.is_file())
    return sorted(files)


class BuildPyWithData(build_py):
    """``build_py`` that also copies ``models/`` and ``datasets/`` into ``hframe_id/_data``."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        for source in shipped_files():
            target = Path(self.build_lib, TARGET, source)
            self.mkpath(str(target.parent))
            self.copy_file(str(ROOT / source), str(target), preserve_mode=False)

    def get_outputs(self, include_bytecode: bool = True) -> list[str]:
        outputs = super().get_outputs(include_bytecode)
        if getattr(self, "editable_mode", False):
            return outputs
        return outputs + [str(Path(self.build_lib, TARGET, s)) for s in shipped_files()]

    def get_source_files(self) -> list[str]:
        return super().get_source_files() + [source.as_posix() for source in shipped_files()]


setup(cmdclass={"build_py": BuildPyWithData})
