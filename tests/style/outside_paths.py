"""Nothing in the tree names a path outside it: a clone of the repository alone must build, test
and run its examples (docs/development.md). Reads every file git tracks (or, given a folder that
is not a repository, every file under it) and reports each line that names a sibling folder of the
checkout (a path that climbs out of the root to a folder beside it) or an absolute path of the machine
it was written on.

  outside_paths.py [--all-files] ROOT   prints each such line as FILE:LINE: TEXT, exit 1 if any
                                        (--all-files: every file under ROOT, not git's list)
"""

import pathlib
import re
import subprocess
import sys

# A relative path climbing out of the repository's root to a named folder beside it, and the
# absolute paths of a developer's machine or CI.
PATTERNS = [re.compile(r"(?<![\w.])\.\./(shared|data|\.library)\b"), re.compile(r"/work/(main|shared)\b"),
            re.compile(r"\.parent\s*/\s*[\"']shared[\"']")]
SKIP_SUFFIXES = {".pbf", ".png", ".gpkg", ".npy", ".bin", ".gz", ".jpg", ".mcap"}


FIXTURE = "tests/style/outside_fixture/"  # the check's own fixture, which names such a path on purpose


def files(root, all_files):
    if all_files:
        return [p for p in root.rglob("*") if p.is_file()]
    try:
        out = subprocess.run(["git", "-C", str(root), "ls-files", "-z"], check=True, capture_output=True).stdout
        return [root / f for f in out.decode().split("\0") if f]
    except (subprocess.CalledProcessError, FileNotFoundError):
        return [p for p in root.rglob("*") if p.is_file()]


def main():
    args = sys.argv[1:]
    all_files = "--all-files" in args
    root = pathlib.Path([a for a in args if a != "--all-files"][0]).resolve()
    found = 0
    for path in files(root, all_files):
        relative = path.relative_to(root).as_posix()
        if path.suffix in SKIP_SUFFIXES or not path.is_file() or relative.startswith(("fuzz/corpus/", FIXTURE)):
            continue
        try:
            text = path.read_text(encoding="utf-8")
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            if any(p.search(line) for p in PATTERNS):
                print(f"{relative}:{number}: {line.strip()[:160]}")
                found += 1
    if found:
        print(f"{found} line(s) name a path outside the repository")
        return 1
    print("no path outside the repository")
    return 0


if __name__ == "__main__":
    sys.exit(main())
