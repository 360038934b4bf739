"""Ship the top-level config/ and scene/ (where people edit them) inside the onebox package.

Everything else about the package is in pyproject.toml; this only copies the two folders into
the built package, so an onebox installed from a wheel or with `pip install .` finds them
(``onebox.settings.data_dir``).
"""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildPyWithData(build_py):  # type: ignore[misc]
    def run(self) -> None:
        super().run()
        for name in ("config", "scene"):
            shutil.copytree(name, Path(self.build_lib) / "onebox" / name, dirs_exist_ok=True)


setup(cmdclass={"build_py": BuildPyWithData})
