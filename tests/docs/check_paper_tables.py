"""docs/paper-tables.md's tables are the ones its results file gives, and the check can fail.

  check_paper_tables.py ROOT   exit 0 when ROOT's page passes bench/paper_tables/write_doc.py
                               --check and a copy with one figure changed does not
"""

import pathlib
import re
import shutil
import subprocess
import sys
import tempfile


def check(writer, root):
    return subprocess.run([sys.executable, str(writer), "--check", "--root", str(root)], capture_output=True, text=True)


def main():
    root = pathlib.Path(sys.argv[1]).resolve()
    writer = root / "bench" / "paper_tables" / "write_doc.py"
    real = check(writer, root)
    print(real.stdout + real.stderr, end="")
    if real.returncode != 0:
        return 1
    with tempfile.TemporaryDirectory(prefix="seqloc-paper-tables-") as scratch:
        copy = pathlib.Path(scratch)
        (copy / "docs").mkdir()
        for name in ("paper-tables.md", "paper-tables.json"):
            shutil.copyfile(root / "docs" / name, copy / "docs" / name)
        page = (copy / "docs" / "paper-tables.md").read_text()
        # The first figure of the first table's SeqLoc row, one tenth up.
        match = re.search(r"^\| \*\*SeqLoc \(defaults\)\*\* \| (\d+\.\d)", page, re.M)
        if not match:
            print("docs/paper-tables.md: no SeqLoc row in the overall table")
            return 1
        changed = f"{float(match.group(1)) + 0.1:.1f}"
        page = page[: match.start(1)] + changed + page[match.end(1) :]
        (copy / "docs" / "paper-tables.md").write_text(page)
        edited = check(writer, copy)
        if edited.returncode == 0:
            print(f"a page whose SeqLoc figure reads {changed} instead of {match.group(1)} passed the check")
            return 1
    print("a page with one figure changed fails the check")
    return 0


if __name__ == "__main__":
    sys.exit(main())
