"""Build hook: the wheel carries the bundled models.

The VJM URDFs are generated into ``models/urdf/`` (``scripts/make_*.py``), the place the
repository shows them. A non-editable install has no source tree, so ``build_py`` copies them
into the package as ``vjm_pin/data/*.urdf``, where :func:`vjm_pin.model.registry.models_dir` finds
them. Everything else is configured in ``pyproject.toml``.
"""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
MODELS = HERE / "models" / "urdf"


class BuildPyWithModels(build_py):
    def run(self):
        super().run()
        target = Path(self.build_lib) / "vjm_pin" / "data"
        target.mkdir(parents=True, exist_ok=True)
        for f in sorted(MODELS.glob("*.urdf")):
            shutil.copyfile(f, target / f.name)


setup(cmdclass={"build_py": BuildPyWithModels})
