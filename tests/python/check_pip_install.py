"""`pip install .` from the repository as docs/python.md tells a user to: into a fresh virtual
environment that sees Debian's numpy, without build isolation and without an index (no network).
The installed package is then imported from another folder and used on a real region cache, and
uninstalled again. SEQLOC_BUILD_DIR points setup.py at the test suite's CMake build, so that the
module is not compiled a second time (setup.py's own build/pip is the same CMake target)."""

import argparse
import os
import subprocess
import sys
import tempfile

USE = r"""
import os, sys
import seqloc
here = os.path.dirname(seqloc.__file__)
assert here.startswith(sys.prefix), f"seqloc imported from {here}, not from the environment {sys.prefix}"
for name in ("py.typed", "_seqloc.pyi"):
    assert os.path.isfile(os.path.join(here, name)), f"{name} is not installed"
cache = seqloc.Cache(sys.argv[1])
crop = cache.crop(cache.info.centre_lat, cache.info.centre_lon, size_m=32.0)
assert crop.classes.shape == (64, 64, 3) and crop.road_distance.dtype.name == "float32", crop
try:
    cache.crop(0.0, 0.0, 32.0)
    raise AssertionError("a point outside the region gave a crop")
except seqloc.RequestError:
    pass
print("seqloc", seqloc.__version__, "from", here)
"""


def run(command, **kwargs):
    print("+", " ".join(command), flush=True)
    result = subprocess.run(command, capture_output=True, text=True, **kwargs)
    if result.returncode != 0:
        sys.exit(f"failed ({result.returncode}): {' '.join(command)}\n{result.stdout[-3000:]}\n{result.stderr[-3000:]}")
    return result.stdout


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--source", required=True, help="the repository")
    parser.add_argument("--build-dir", required=True, help="a configured CMake build of it")
    parser.add_argument("--cache", required=True, help="a region cache to use the package on")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as work:
        venv = os.path.join(work, "venv")
        run([sys.executable, "-m", "venv", "--system-site-packages", venv])
        python = os.path.join(venv, "bin", "python")
        env = dict(os.environ, SEQLOC_BUILD_DIR=args.build_dir, PIP_NO_INDEX="1", PIP_DISABLE_PIP_VERSION_CHECK="1")
        env.pop("PYTHONPATH", None)
        run([python, "-m", "pip", "install", "--no-build-isolation", "--no-index", args.source], env=env, cwd=work)
        print(run([python, "-c", USE, args.cache], env=env, cwd=work), end="")
        run([python, "-m", "pip", "uninstall", "--yes", "seqloc"], env=env, cwd=work)
        gone = subprocess.run([python, "-c", "import seqloc"], capture_output=True, text=True, env=env, cwd=work)
        if gone.returncode == 0:
            sys.exit("seqloc still imports after pip uninstall")
    print("pip install . and uninstall: ok")


if __name__ == "__main__":
    main()
