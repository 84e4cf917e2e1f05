"""What the base layer (core/) gives is taken from it, not written again: pi and the degree-radian
factors (core/angles.hpp), committing a finished file (core/files.hpp) and the default thread count
(core/thread_pool.hpp). Reads the C++ and CUDA sources of every folder but core/ and tests/ and
reports each line that writes one of them by hand; comments and string literals are not read.

  base_layer.py [--all-files] ROOT   prints each such line as FILE:LINE: what to use instead, exit 1
                                    if any (the files git tracks under ROOT; --all-files: every file)
"""

import pathlib
import re
import sys

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from function_length import blank  # noqa: E402  comments and literals blanked, raw strings too
from outside_paths import files  # noqa: E402  the files git tracks (or every file)

CHECKS = [
    (re.compile(r"\bM_PI\w*\b"), "pi: core::kPi, core::kDegToRad, core::kRadToDeg (core/angles.hpp)"),
    (re.compile(r"\b3\.14159"), "pi: core::kPi, core::kDegToRad, core::kRadToDeg (core/angles.hpp)"),
    (re.compile(r"\brename(at2?)?\s*\("), "a file committed by hand: core::commit_file (core/files.hpp)"),
    (re.compile(r"\bhardware_concurrency\s*\("), "the default thread count: core::default_threads (core/thread_pool.hpp)"),
]
SUFFIXES = {".cpp", ".hpp", ".h", ".cc", ".cu", ".cuh"}
SKIP = {"core", "tests"}


def sources(root, all_files):
    for path in sorted(files(root, all_files)):
        relative = path.relative_to(root)
        if path.suffix in SUFFIXES and path.is_file() and len(relative.parts) > 1 and relative.parts[0] not in SKIP:
            yield path, relative.as_posix()


def main():
    args = sys.argv[1:]
    root = pathlib.Path([a for a in args if a != "--all-files"][0]).resolve()
    found = 0
    for path, relative in sources(root, "--all-files" in args):
        for number, line in enumerate(blank(path.read_text(encoding="utf-8")).splitlines(), 1):
            for pattern, instead in CHECKS:
                if pattern.search(line):
                    print(f"{relative}:{number}: {instead}")
                    found += 1
    if found:
        print(f"{found} line(s) write by hand what the base layer gives")
        return 1
    print("pi, file commits and the default thread count come from core")
    return 0


if __name__ == "__main__":
    sys.exit(main())
