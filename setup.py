"""seqloc's Python package for pip (pyproject.toml): python/seqloc with its compiled module
seqloc._seqloc, which CMake builds (target seqloc_python) in build/pip, or in the CMake build
folder SEQLOC_BUILD_DIR names (one already configured, such as the test suite's)."""

import os
import pathlib
import re
import shutil
import subprocess
import sys

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = pathlib.Path(__file__).resolve().parent


def project_version() -> str:
    """The version CMakeLists.txt gives the project (one place for it)."""
    match = re.search(r"project\(seqloc VERSION ([0-9.]+)", (ROOT / "CMakeLists.txt").read_text())
    if not match:
        raise RuntimeError("CMakeLists.txt: no 'project(seqloc VERSION x.y.z' line")
    return match.group(1)


class CMakeBuild(build_ext):
    """Builds seqloc._seqloc with the project's CMake and copies it where setuptools packs it."""

    def build_extension(self, ext: Extension) -> None:
        build_dir = pathlib.Path(os.environ.get("SEQLOC_BUILD_DIR") or ROOT / "build" / "pip").resolve()
        if not (build_dir / "CMakeCache.txt").exists():
            self.announce(f"configuring seqloc in {build_dir}", level=3)
            subprocess.run(["cmake", "-S", str(ROOT), "-B", str(build_dir), "-DCMAKE_BUILD_TYPE=Release",
                            "-DSEQLOC_BUILD_TESTS=OFF", "-DSEQLOC_WERROR=OFF",
                            f"-DPython3_EXECUTABLE={sys.executable}"], check=True)
        jobs = os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL") or str(os.cpu_count() or 1)
        subprocess.run(["cmake", "--build", str(build_dir), "--target", "seqloc_python", "--parallel", jobs],
                       check=True)
        built = sorted((build_dir / "python" / "seqloc").glob("_seqloc.*.so"))
        if len(built) != 1:
            raise RuntimeError(f"{build_dir}/python/seqloc: expected one _seqloc module, found {len(built)}")
        target = pathlib.Path(self.get_ext_fullpath(ext.name))
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(built[0], target)


setup(
    version=project_version(),
    packages=["seqloc"],
    package_dir={"": "python"},
    package_data={"seqloc": ["_seqloc.pyi", "py.typed"]},
    ext_modules=[Extension("seqloc._seqloc", sources=[])],
    cmdclass={"build_ext": CMakeBuild},
    # setuptools' own scratch under build/pip too, beside CMake's, not in the test suite's build/.
    options={"build": {"build_base": str(ROOT / "build" / "pip" / "setuptools")}},
    zip_safe=False,
)
