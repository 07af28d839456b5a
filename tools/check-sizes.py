#!/usr/bin/env python3
"""The library crates stay readable: no function over 150 lines, no file over 1,000 lines.

Checks every `.rs` file under the library crates' `src/` (rt, rt/model, actors, transport and
tools' library; not binaries' `src/bin/`, not test code: `tests.rs` files, `tests/` directories,
and `#[cfg(test)]` modules are skipped). A function's length is counted from its `fn` line to its
closing brace; a file's is its lines less its `#[cfg(test)]` modules. Prints each offender with its file and line and exits 1 if there is one.

Usage: tools/check-sizes.py [--max-fn N] [--max-file N] [--list K]
  --list K  also print the K longest functions and files (to see the margin)
"""

import argparse
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parent.parent
CRATES = ["rt/src", "rt/model/src", "actors/src", "transport/src", "tools/src"]
FN = re.compile(r"^\s*(?:pub(?:\([^)]*\))?\s+)?(?:const\s+)?(?:async\s+)?(?:unsafe\s+)?(?:extern\s+\"[^\"]*\"\s+)?fn\s+(\w+)")
CFG_TEST = re.compile(r"^\s*#\[cfg\(test\)\]")


def strip(text):
    """The source with comments, strings and char literals blanked (newlines kept), so braces
    count only as code."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
            i = j
        elif re.match(r'b?r#*"', text[i:i + 40]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'(b?r)(#*)"', text[i:])
            end = '"' + m.group(2)
            j = text.find(end, i + len(m.group(0)))
            j = n if j < 0 else j + len(end)
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
            i = j
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == "\\" else 1
            j += 1
            out.append("".join(ch if ch == "\n" else " " for ch in text[i:j]))
            i = j
        elif c == "'":
            # A char literal ('{', '\n', '\u{7f}'), not a lifetime ('a).
            m = re.match(r"'(\\u\{[0-9a-fA-F]+\}|\\.|[^\\'])'", text[i:])
            if m:
                out.append(" " * len(m.group(0)))
                i += len(m.group(0))
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def closing_line(lines, start):
    """The line (0-based) of the brace closing the first `{` at or after `start`, or None for a
    declaration without a body."""
    depth, opened, nest = 0, False, 0
    for k in range(start, len(lines)):
        for ch in lines[k]:
            if ch in "([":
                nest += 1
            elif ch in ")]":
                nest -= 1
            elif ch == "{":
                depth, opened = depth + 1, True
            elif ch == "}":
                depth -= 1
                if opened and depth == 0:
                    return k
            elif ch == ";" and not opened and nest == 0:
                # `;` ends a declaration only outside brackets: `[T; N]` in a signature does not.
                return None
    return None


def check(path):
    raw = path.read_text()
    lines = strip(raw).split("\n")
    raw_lines = raw.split("\n")
    fns, skip_until, test_lines = [], -1, 0
    for k, line in enumerate(lines):
        if k <= skip_until:
            continue
        if CFG_TEST.match(raw_lines[k]):
            end = closing_line(lines, k + 1)
            skip_until = end if end is not None else k
            test_lines += skip_until - k + 1
            continue
        m = FN.match(line)
        if m:
            end = closing_line(lines, k)
            if end is not None:
                fns.append((end - k + 1, m.group(1), k + 1))
    return len(raw.rstrip("\n").split("\n")) - test_lines, fns


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--max-fn", type=int, default=150)
    ap.add_argument("--max-file", type=int, default=1000)
    ap.add_argument("--list", type=int, default=0)
    a = ap.parse_args()
    bad, files, fns = [], [], []
    for crate in CRATES:
        for p in sorted((ROOT / crate).rglob("*.rs")):
            rel = p.relative_to(ROOT)
            parts = rel.parts
            if "bin" in parts or "tests" in parts or p.name == "tests.rs":
                continue
            length, found = check(p)
            files.append((length, str(rel)))
            if length > a.max_file:
                bad.append(f"{rel}: {length} lines (the rule: at most {a.max_file} lines a file)")
            for n, name, line in found:
                fns.append((n, f"{rel}:{line} fn {name}"))
                if n > a.max_fn:
                    bad.append(f"{rel}:{line}: fn {name} is {n} lines (the rule: at most {a.max_fn} lines a function)")
    if a.list:
        print("longest files:")
        for n, what in sorted(files, reverse=True)[: a.list]:
            print(f"  {n:5} {what}")
        print("longest functions:")
        for n, what in sorted(fns, reverse=True)[: a.list]:
            print(f"  {n:5} {what}")
    for b in bad:
        print(b, file=sys.stderr)
    if bad:
        print(f"{len(bad)} over the limits: split where the concepts part (CONTRIBUTING.md)", file=sys.stderr)
        return 1
    print(f"sizes: {len(files)} files, {len(fns)} functions within {a.max_file} and {a.max_fn} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main())
