#!/usr/bin/env python3
"""Checks the options tables of docs/commands/*.md against `demcal ... --help` (the same rules as
tests/pipelines/test_docs.cpp, for a quick check without building the tests).

    python3 scripts/check-options-tables.py build/demcal

Rules: every command path (`demcal`, `demcal calibrate`, `demcal scene arch`, ...) whose --help
prints long flags besides --help has rows in the options tables of its page: the tables under a
heading that contains "options" and the code span `demcal PATH`. A row's first cell is one code
span holding the option's names exactly as --help prints them (`-o,--output`). The rows name every
long flag the help prints and no other. `--help` and the program's own options (those of
`demcal --help`, such as `--limit`) are documented once, in docs/commands/README.md. Every page
has at most 400 lines. Exit status 1 with one line per difference."""
import os
import re
import subprocess
import sys

LONG_FLAG = re.compile(r"--[a-z0-9][a-z0-9-]*")
MAX_PAGE_LINES = 400


def help_text(binary, path):
    return subprocess.run([binary, *path, "--help"], capture_output=True, text=True, check=True).stdout


def parse_help(text):
    """(option names as printed, e.g. '-o,--output'; subcommand names)."""
    names, subcommands, section = [], [], ""
    for line in text.splitlines():
        if line and not line.startswith(" "):
            section = line.rstrip(":")
            continue
        m = re.match(r"^ {2}(-\S+)", line)
        if m:
            names.append(re.sub(r"\{[^}]*\}$", "", m.group(1)))
        elif section == "Subcommands":
            m = re.match(r"^ {2}([a-z][a-z0-9-]*)(\s|$)", line)
            if m:
                subcommands.append(m.group(1))
    return names, subcommands


def page_tables(page_text):
    """{command path (tuple): [first cells of the rows]} for every options heading of a page."""
    tables, current, fence = {}, None, False
    lines = page_text.splitlines()
    separator = re.compile(r"^\|[\s:|-]+\|$")
    for i, line in enumerate(lines):
        if line.startswith("```"):
            fence = not fence
            continue
        if fence:
            continue
        if re.match(r"^#{1,6} ", line):
            current = None
            if "options" in line.lower():
                current = [tuple(span.split()[1:]) for span in re.findall(r"`(demcal(?: [a-z][a-z0-9-]*)*)`", line)]
                for path in current:
                    tables.setdefault(path, [])
            continue
        if current is None or not line.startswith("|") or separator.match(line.strip()):
            continue
        if i + 1 < len(lines) and separator.match(lines[i + 1].strip()):
            continue  # a table's header row
        cell = line.split("|")[1].strip()
        for path in current:
            tables[path].append(cell)
    return tables


def main():
    binary = sys.argv[1] if len(sys.argv) > 1 else "build/demcal"
    docs = sys.argv[2] if len(sys.argv) > 2 else os.path.join(os.path.dirname(__file__), "..", "docs", "commands")
    errors = []
    root_names, top = parse_help(help_text(binary, []))
    global_flags = {f for n in root_names for f in LONG_FLAG.findall(n)}
    paths = [()]
    for name in top:
        paths.append((name,))
        paths += [(name, sub) for sub in parse_help(help_text(binary, [name]))[1]]
    pages = {}
    for path in paths:
        page = os.path.join(docs, (path[0] + ".md") if path else "README.md")
        if not os.path.exists(page):
            errors.append(f"{page}: missing (the page of `demcal {' '.join(path)}`)")
            continue
        if page not in pages:
            text = open(page, encoding="utf-8").read()
            pages[page] = page_tables(text)
            if text.count("\n") > MAX_PAGE_LINES:
                errors.append(f"{page}: {text.count(chr(10))} lines, more than {MAX_PAGE_LINES}")
        names, _ = parse_help(help_text(binary, list(path)))
        skip = ({"--help"} | global_flags) if path else set()
        expected = {n for n in names if not set(LONG_FLAG.findall(n)) & skip}
        cells = pages[page].get(path, [])
        label = "demcal " + " ".join(path) if path else "demcal"
        documented, valid = set(), 0
        for cell in cells:
            m = re.fullmatch(r"`(-[^`\s]+)`", cell)
            if not m:
                errors.append(f"{page}: `{label}`: row '{cell}' is not one code span naming an option")
                continue
            documented.add(m.group(1))
            valid += 1
        for name in sorted(expected - documented):
            errors.append(f"{page}: `{label}`: no row for {name}, which --help prints")
        for name in sorted(documented - expected):
            errors.append(f"{page}: `{label}`: row {name} is not an option --help prints")
        if valid != len(documented):
            errors.append(f"{page}: `{label}`: an option has two rows")
    for page, tables in pages.items():
        for path in tables:
            if path not in paths:
                errors.append(f"{page}: options heading names `demcal {' '.join(path)}`, which is no command")
    for e in errors:
        print(e)
    print(f"{len(paths)} commands, {len(errors)} differences")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
