"""The wheel's package data beyond pyproject.toml: the checkout's networks/, protocols/ and routes/ copied
into the package as pedsafe_sumo/_shipped/, where an installed package finds them (pedsafe_sumo.NETWORKS_DIR
and its siblings). A checkout and an editable install read the folders where they are."""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
#: The folders shipped with the package. osm/ is not: it is needed only to rebuild a site, and the sites
#: carry the OpenStreetMap attribution themselves (networks/README.md, the header of every file).
SHIPPED = ("networks", "protocols", "routes")


class BuildWithShippedData(build_py):
    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):  # an editable install reads the checkout's folders
            return
        target = Path(self.build_lib) / "pedsafe_sumo" / "_shipped"
        shutil.rmtree(target, ignore_errors=True)  # a file deleted from the checkout leaves the wheel too
        for folder in SHIPPED:
            if (ROOT / folder).is_dir():  # an sdist holds them too (MANIFEST.in)
                shutil.copytree(ROOT / folder, target / folder, dirs_exist_ok=True)


setup(cmdclass={"build_py": BuildWithShippedData})
