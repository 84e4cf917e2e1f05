"""The README runs as written: every ```sh block of README.md, in order, as one bash script in a
scratch folder that sees the repository's build/, data/ and samples/ (the commands are written from
the repository's root). A block whose first line says it is the set-up or that the README test does
not run it is left out; the page says so to its reader in the same words.

  run_readme.py README BUILD   runs the blocks; exit 0 when every command succeeded

It also checks that the benchmark figures the README quotes are the ones docs/paper-tables.md
holds (one source for each figure).
"""

import os
import pathlib
import re
import signal
import subprocess
import sys
import tempfile

SKIP = re.compile(r"^#\s*(set-up\b|not run by the README test\b)")


def blocks(text):
    for match in re.finditer(r"^```sh\n(.*?)^```", text, re.S | re.M):
        body = match.group(1)
        first = body.lstrip().splitlines()[0] if body.strip() else ""
        yield body, bool(SKIP.match(first))


def check_figures(readme, tables):
    # The sentence that quotes the benchmark: each percentage in it must be in the tables' page.
    match = re.search(r"The benchmark on real OSM regions is the measure(.*?)\n\n", readme, re.S)
    if not match:
        print("README: no sentence quoting the benchmark (\"The benchmark on real OSM regions is the measure\")")
        return False
    figures = re.findall(r"(\d+\.\d) %", match.group(1))
    missing = [f for f in figures if not re.search(r"\b" + re.escape(f) + r"\b", tables)]
    if not figures or missing:
        print(f"README quotes {figures}; not in docs/paper-tables.md: {missing}")
        return False
    print(f"README's benchmark figures {figures} are in docs/paper-tables.md")
    return True


def main():
    readme_path, build = pathlib.Path(sys.argv[1]).resolve(), pathlib.Path(sys.argv[2]).resolve()
    root = readme_path.parent
    readme = readme_path.read_text()
    ok = check_figures(readme, (root / "docs" / "paper-tables.md").read_text())
    run, skipped = [], 0
    for body, skip in blocks(readme):
        if skip:
            skipped += 1
        else:
            run.append(body)
    if not run:
        print("README: no block to run")
        return 1
    # Each command echoed with the seconds since the start, so a slow or failing one is found.
    script = "set -euo pipefail\nPS4='+ [${SECONDS} s] '\nset -x\n" + "\n".join(run)
    with tempfile.TemporaryDirectory(prefix="seqloc-readme-") as scratch:
        work = pathlib.Path(scratch)
        os.symlink(build, work / "build")
        for name in ("data", "samples"):
            os.symlink(root / name, work / name)
        print(f"running {len(run)} blocks of README.md ({skipped} left out, as marked) in {work}", flush=True)
        # Debian's python3 first, as on the fresh Debian machine the README is written for (the
        # module is built for it; another interpreter earlier on PATH may lack NumPy).
        env = dict(os.environ, PATH="/usr/bin:" + os.environ.get("PATH", ""))
        # In a session of its own: a server a failing block started in the background is stopped
        # with the rest (it would otherwise hold the port, and ctest's pipes, after the test).
        process = subprocess.Popen(["bash", "-c", script], cwd=work, env=env, start_new_session=True)
        try:
            returncode = process.wait(timeout=1200)
        finally:
            try:
                os.killpg(process.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        if returncode != 0:
            print(f"README.md: the blocks failed (exit {returncode}); the command is the last '+' line above")
            return 1
    print("README.md runs as written")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
