"""No function over a line limit in the libraries, apps and the Python module (docs/development.md,
"Code"). A function is a brace block opened at namespace or class scope after a parameter list:
its length runs from the first line of its signature to its closing brace, lambdas and nested
blocks included. Comments, string and character literals (raw strings too) are blanked first, so
their braces do not count.

  function_length.py [--limit N] ROOT [FOLDER ...]   prints the functions over the limit, exit 1 if any
"""

import argparse
import pathlib
import re
import sys

FOLDERS = ["core", "osm", "raster", "intake", "selfcal", "filter", "offline", "uncertainty", "gpu", "ingest", "io", "matcher", "sim", "ros", "pipeline", "render", "serve",
           "apps", "python"]
SUFFIXES = {".cpp", ".hpp", ".cu", ".cuh", ".h"}
CONTROL = re.compile(r"\b(if|for|while|switch|catch|do|else|try)\s*(\(.*\))?\s*$", re.S)


def blank(text):
    """The text with comments and literals replaced by spaces (newlines kept)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
        elif c == "R" and i + 1 < n and text[i + 1] == '"' and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            if not m:
                out.append(c)
                i += 1
                continue
            j = text.find(")" + m.group(1) + '"', i + m.end())
            j = n if j < 0 else j + len(m.group(1)) + 2
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            if c == "'" and i > 0 and text[i - 1].isalnum():  # a digit separator: 1'000'000
                out.append(c)
                i += 1
                continue
        else:
            out.append(c)
            i += 1
            continue
        out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
        i = j
    return "".join(out)


def functions(text):
    """(name, first line, last line) of each function body at namespace or class scope."""
    code = blank(text)
    stack = []  # (kind, start line, name)
    header_start = 0
    found = []
    for i, c in enumerate(code):
        if c not in "{};":
            continue
        if c == ";":
            header_start = i + 1
            continue
        if c == "}":
            kind, first, name = stack.pop() if stack else ("other", 0, "")
            if kind == "function":
                found.append((name, first, code.count("\n", 0, i) + 1))
            header_start = i + 1
            continue
        header = code[header_start:i]
        inside = stack[-1][0] if stack else "namespace"
        kind = "other"
        if inside in ("namespace", "class"):
            flat = " ".join(header.split())
            if re.search(r"\bnamespace\b|extern \"", header) or flat.startswith("extern"):
                kind = "namespace"
            elif re.search(r"\b(class|struct|union|enum)\b", flat) and "(" not in flat.split("{")[0]:
                kind = "class"
            elif ")" in flat and not CONTROL.search(flat) and not flat.endswith("="):
                kind = "function"
        lead = len(header) - len(header.lstrip())
        first = code.count("\n", 0, header_start + lead) + 1
        name = ""
        if kind == "function":
            m = re.search(r"([~\w:<>]+)\s*\(", header)
            name = m.group(1) if m else "?"
        stack.append((kind, first, name))
        header_start = i + 1
    return found


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("root")
    parser.add_argument("folders", nargs="*", default=FOLDERS)
    parser.add_argument("--limit", type=int, default=80)
    args = parser.parse_args()
    root = pathlib.Path(args.root)
    over = []
    for folder in args.folders:
        for path in sorted((root / folder).rglob("*")):
            if path.suffix in SUFFIXES and path.is_file():
                for name, first, last in functions(path.read_text(errors="replace")):
                    if last - first + 1 > args.limit:
                        over.append((last - first + 1, f"{path.relative_to(root)}:{first}", name))
    for lines, where, name in sorted(over, reverse=True):
        print(f"{where}: {name} is {lines} lines (limit {args.limit})")
    if over:
        sys.exit(1)
    print(f"no function over {args.limit} lines in {', '.join(args.folders)}")


if __name__ == "__main__":
    main()
