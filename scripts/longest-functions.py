#!/usr/bin/env python3
"""Lists the longest C++ functions of the library code, with file:line and length in lines.

    python3 scripts/longest-functions.py              # the ten longest under the module folders
    python3 scripts/longest-functions.py --top 30 dem pipelines/diagnose
    python3 scripts/longest-functions.py --over 120   # every function longer than 120 lines

A function's length counts the lines from the start of its declaration (template line included)
to its closing brace. Found by brace matching, not by a compiler: comments, string and character
literals and preprocessor lines are blanked first; a `{` at namespace or class scope opens a
function body when the text before it (since the last `;`, `{` or `}`) has a parameter list and
ends with `)`, a qualifier (`const`, `noexcept`, `override`, `final`, `mutable`) or a trailing
return type; `namespace`, `class`, `struct`, `union`, `enum` and `extern "C"` open scopes that are
searched in turn; anything else (an initialiser) is skipped. Lambdas and local classes count in
the function that holds them. Method: docs/code-size.md."""
import argparse
import os
import re
import sys

DEFAULT_FOLDERS = ["dem", "optimise", "smoothing", "surrogate", "pipelines", "limits", "common"]
EXTENSIONS = (".cpp", ".hpp", ".h", ".cc")
QUALIFIERS = r"(?:\s*(?:const|noexcept(?:\s*\([^)]*\))?|override|final|mutable|&|&&))*"
FUNCTION_END = re.compile(r"\)" + QUALIFIERS + r"\s*(?:->\s*[\w:<>,\s*&\[\]]+)?\s*$")
INIT_LIST = re.compile(r"\)" + QUALIFIERS + r"\s*:\s*[^:]")
SCOPE = re.compile(r"^(?:template\s*<.*>\s*)?(?:inline\s+)?(namespace|class|struct|union|enum|extern\s+\"C\")\b")


def blank(text):
    """The text with comments, literals and preprocessor lines replaced by spaces (newlines kept)."""
    out, i, n = [], 0, len(text)
    at_line_start = True
    while i < n:
        c = text[i]
        if at_line_start and c == "#":
            j = i
            while j < n and (text[j] != "\n" or text[j - 1] == "\\"):
                j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
            continue
        if c in " \t":
            out.append(c)
            i += 1
            continue
        at_line_start = c == "\n"
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "R" and text.startswith('R"', i) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'R"([^(\s]*)\(', text[i:])
            if not m:
                out.append(c)
                i += 1
                continue
            end = text.find(")" + m.group(1) + '"', i)
            j = n if end < 0 else end + len(m.group(1)) + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c in "\"'":
            if c == "'" and i > 0 and text[i - 1].isalnum():  # a digit separator: 1'000'000
                out.append(" ")
                i += 1
                continue
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            out.append(" " * (min(j + 1, n) - i))
            i = j + 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def matching_brace(text, i):
    depth = 0
    for j in range(i, len(text)):
        if text[j] == "{":
            depth += 1
        elif text[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(text) - 1


def function_name(head):
    """The name before the parameter list: the first '(' outside template brackets."""
    depth = 0
    for k, c in enumerate(head):
        if c == "<":
            depth += 1
        elif c == ">" and depth > 0:
            depth -= 1
        elif c == "(" and depth == 0:
            if head[:k].rstrip().endswith("operator"):
                continue  # operator(): the first parentheses are the name's
            m = re.search(r"((?:[\w~]+::)*(?:operator\s*\S+|~?\w+))\s*$", head[:k])
            return m.group(1) if m else "?"
    return "?"


def functions(text):
    """(first line, last line, name) of every function body at namespace or class scope."""
    found = []
    line_of = [0] * (len(text) + 1)
    line = 1
    for k, c in enumerate(text):
        line_of[k] = line
        if c == "\n":
            line += 1
    line_of[len(text)] = line

    def scan(start, end):
        head_start, i = start, start
        while i < end:
            c = text[i]
            if c in ";}":
                head_start = i + 1
            elif c == "{":
                head = text[head_start:i]
                stripped = head.strip()
                close = matching_brace(text, i)
                if SCOPE.match(stripped) and "(" not in stripped.split("{")[0].split(":")[0]:
                    scan(i + 1, close)           # a namespace or class: search its body
                    head_start = close + 1
                    i = close
                elif re.search(r"\w$", stripped) and INIT_LIST.search(stripped):
                    i = close                    # a member initialiser's braces: the head goes on
                elif "(" in stripped and FUNCTION_END.search(stripped) and not re.search(r"=\s*[^=]", _outside_parens(stripped)):
                    first = head_start + (len(head) - len(head.lstrip()))
                    found.append((line_of[first], line_of[close], function_name(stripped)))
                    head_start = close + 1
                    i = close
                else:
                    head_start = close + 1       # an initialiser, an enum's list: skipped
                    i = close
            i += 1

    scan(0, len(text))
    return found


def _outside_parens(head):
    depth, out = 0, []
    for c in head:
        if c in "(<[":
            depth += 1
        elif c in ")>]" and depth > 0:
            depth -= 1
        elif depth == 0:
            out.append(c)
    return "".join(out).replace("operator=", "").replace("==", "").replace("!=", "").replace("<=", "").replace(">=", "")


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("folders", nargs="*", help="folders or files (default: the module folders)")
    parser.add_argument("--top", type=int, default=10, help="how many to list (default 10)")
    parser.add_argument("--over", type=int, default=0, help="list every function longer than this instead")
    args = parser.parse_args()
    root = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))
    targets = args.folders or [os.path.join(root, f) for f in DEFAULT_FOLDERS]
    files = []
    for target in targets:
        if os.path.isfile(target):
            files.append(target)
        for folder, _, names in os.walk(target):
            files += [os.path.join(folder, name) for name in names if name.endswith(EXTENSIONS)]
    rows = []
    for path in sorted(set(files)):
        with open(path, encoding="utf-8", errors="replace") as f:
            text = blank(f.read())
        for first, last, name in functions(text):
            rows.append((last - first + 1, os.path.relpath(path, root), first, name))
    rows.sort(key=lambda r: (-r[0], r[1], r[2]))
    chosen = [r for r in rows if r[0] > args.over] if args.over else rows[: args.top]
    print(f"{'lines':>5}  {'where':<52} function")
    for length, path, first, name in chosen:
        print(f"{length:>5}  {path + ':' + str(first):<52} {name}")
    print(f"({len(rows)} functions in {len(set(files))} files)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
