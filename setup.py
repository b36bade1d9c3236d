"""Build hook: the wheel carries a copy of the nominal arm, the examples, the docs and the README (package data of
arm_model, under arm_model/_shipped/), so an installed toolkit works without a clone.
Everything else is declared in pyproject.toml."""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
SHIPPED = {"urdf/aacmm7.dh.toml": "urdf/aacmm7.dh.toml", "urdf/aacmm7.urdf": "urdf/aacmm7.urdf",
           "examples": "examples", "docs": "docs", "README.md": "README.md"}


class BuildWithShipped(build_py):
    def run(self):
        super().run()
        if self.editable_mode:          # an editable install reads the checkout itself
            return
        target = Path(self.build_lib) / "arm_model" / "_shipped"
        for src, dst in SHIPPED.items():
            s, d = HERE / src, target / dst
            if s.is_dir():
                shutil.copytree(s, d, dirs_exist_ok=True, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
            elif s.is_file():
                d.parent.mkdir(parents=True, exist_ok=True)
                shutil.copy2(s, d)


setup(cmdclass={"build_py": BuildWithShipped})
