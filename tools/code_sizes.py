#!/usr/bin/env python3
"""Count function and file sizes in the workspace's Rust sources (issue 30, item 5).

Prints every function longer than --fn-max lines and every non-test source file longer than
--file-max lines (lines before a file's `#[cfg(test)] mod tests`). Test code (`tests/`,
`tests.rs`, and the `#[cfg(test)]` module at the end of a file) is not counted. Exits 1 when
anything is over, so CI can run it as a check.

Usage: tools/code_sizes.py [--fn-max 150] [--file-max 1200] [--all]
"""
import argparse
import pathlib
import re
import sys

FN_RE = re.compile(r"^\s*(pub(\([^)]*\))?\s+)?(const\s+)?(async\s+)?(unsafe\s+)?(extern\s+\"[^\"]*\"\s+)?fn\s+(\w+)")


def strip_strings(line):
    """Blank out string/char literals and line comments so braces inside them do not count."""
    line = re.sub(r'"(\\.|[^"\\])*"', '""', line)
    line = re.sub(r"'(\\.|[^'\\])'", "''", line)
    i = line.find("//")
    return line if i < 0 else line[:i]


def is_test_file(path):
    parts = path.parts
    return "tests" in parts or path.name in ("tests.rs",) or "benches" in parts or path.name.endswith("_tests.rs")


def non_test_lines(lines):
    """Lines before the file's `#[cfg(test)]` module (the convention: tests at the bottom)."""
    for i, line in enumerate(lines):
        if line.strip() == "#[cfg(test)]" and i + 1 < len(lines) and re.match(r"\s*mod\s+\w+", lines[i + 1]):
            if not lines[i + 1].rstrip().endswith(";"):
                return lines[:i]
    return lines


def functions(lines):
    """(name, first line, length) of every fn with a body, by brace matching."""
    out = []
    i = 0
    n = len(lines)
    while i < n:
        m = FN_RE.match(lines[i])
        if not m:
            i += 1
            continue
        depth = 0
        started = False
        j = i
        while j < n:
            s = strip_strings(lines[j])
            if not started and ";" in s and "{" not in s:
                break  # a declaration without a body (trait item)
            for ch in s:
                if ch == "{":
                    depth += 1
                    started = True
                elif ch == "}":
                    depth -= 1
            if started and depth <= 0:
                break
            j += 1
        if started:
            out.append((m.group(7), i + 1, j - i + 1))
        i += 1  # nested fns are counted too
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--fn-max", type=int, default=150)
    ap.add_argument("--file-max", type=int, default=1200)
    ap.add_argument("--all", action="store_true", help="list test code too")
    ap.add_argument("root", nargs="?", default=".")
    a = ap.parse_args()
    root = pathlib.Path(a.root)
    over = 0
    for path in sorted(root.glob("crates/**/*.rs")):
        rel = path.relative_to(root)
        if "target" in rel.parts or "fuzz" in rel.parts:
            continue
        if is_test_file(rel) and not a.all:
            continue
        lines = path.read_text(encoding="utf-8").splitlines()
        body = lines if a.all else non_test_lines(lines)
        if len(body) > a.file_max:
            print(f"file {rel}: {len(body)} lines (non-test)")
            over += 1
        for name, start, length in functions(body):
            if length > a.fn_max:
                print(f"fn   {rel}:{start} {name}: {length} lines")
                over += 1
    print(f"{over} over the limits (functions > {a.fn_max} lines, files > {a.file_max} lines)")
    return 1 if over else 0


if __name__ == "__main__":
    sys.exit(main())
