#!/usr/bin/env python3
"""long_functions.py ROOT [--all]: lists every function of the project's C++ sources (outside
tests/ and build folders) longer than MAX_LINES lines, from the first line of its signature to its
closing brace, lambdas inside it included, and exits 1 when one is not on the allowlist below
(issue 51: "no non-test function over 100 lines unless it is a table literal"). --all lists the
allowed ones too. Run by CTest (tests/architecture/CMakeLists.txt, label architecture).

The scanner is a brace matcher, not a C++ parser: comments, string and character literals and
preprocessor lines are blanked first; a '{' at namespace or class scope opens a function when the
text before it, back to the previous ';', '{' or '}', ends in a parameter list (')' then only
qualifiers or a trailing return type) and holds no '=' (a '=' makes it an initializer: a table or
a lambda bound to a name, which is no function). Braces of a class, struct, union, enum or
namespace are scopes whose member functions are measured one by one."""
import os
import re
import sys

MAX_LINES = 100

# Functions allowed to stay longer, as "path:name" with why. Keep this short: a table literal
# (a list of declarations that reads as one table) is the only lasting reason.
ALLOWED = {
    "oiiotool-ext/cli.cpp:buildTable": "the command table: one initializer of every command",
}

# Not yet shortened on this branch (issue 51 §2): listed so that the test names what remains
# rather than failing the suite; each entry goes when its function is split.
REMAINING = {
}

SOURCE_EXT = (".cpp", ".cc", ".cxx", ".h", ".hpp")
SKIP_DIRS = {"tests", ".git", "node_modules", "__pycache__"}


def blank(text):
    """Comments, literals and preprocessor lines replaced by spaces; newlines kept."""
    out = []
    i, n = 0, len(text)
    line_start = True
    while i < n:
        c = text[i]
        if line_start and c in " \t":
            out.append(c)
            i += 1
            continue
        if line_start and c == "#":  # a preprocessor line, with its continuations
            while i < n and text[i] != "\n":
                if text[i] == "\\" and i + 1 < n and text[i + 1] == "\n":
                    out.append(" \n")
                    i += 2
                    continue
                out.append(" ")
                i += 1
            continue
        line_start = False
        if text.startswith("//", i):
            while i < n and text[i] != "\n":
                out.append(" ")
                i += 1
            continue
        if text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
            continue
        m = re.match(r'R"([^()\\ ]{0,16})\(', text[i:i + 20])
        if m and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            end = text.find(")" + m.group(1) + '"', i)
            j = n if end < 0 else end + len(m.group(1)) + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
            continue
        if c in "\"'":
            if c == "'" and i > 0 and text[i - 1].isalnum():  # a digit separator: 1'000
                out.append(" ")
                i += 1
                continue
            j = i + 1
            while j < n and text[j] != c and text[j] != "\n":
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(c + re.sub(r"[^\n]", " ", text[i + 1:j - 1]) + c if j - i >= 2 else c)
            i = j
            continue
        out.append(c)
        if c == "\n":
            line_start = True
        i += 1
    return "".join(out)


SCOPE = re.compile(r"\b(namespace|class|struct|union|enum)\b")
EXTERN = re.compile(r'\bextern\s*"\s*"\s*$')
FUNCTION_END = re.compile(
    r"\)\s*(?:(?:const|noexcept(?:\s*\([^)]*\))?|override|final|mutable|volatile|&&|&)\s*)*"
    r"(?:->\s*[\w:<>,\s\*&]+)?$")


def functions(text):
    """(first line, last line, name) of every function at namespace or class scope."""
    found = []
    n = len(text)
    i = 0
    header_start = 0  # where the text before the next '{' of this scope begins
    while i < n:
        c = text[i]
        if c in ";}":
            header_start = i + 1
        elif c == "{":
            header = text[header_start:i]
            flat = " ".join(header.split())
            paren = flat.find("(")
            scope_part = flat if paren < 0 else flat[:paren]
            if "=" not in flat and SCOPE.search(scope_part) or EXTERN.search(flat):
                header_start = i + 1  # a scope: its members are scanned as they come
            elif "=" not in flat and FUNCTION_END.search(flat.rstrip()):
                end = match_brace(text, i)
                first = header_start + (len(header) - len(header.lstrip()))
                first_line = text.count("\n", 0, first) + 1
                last_line = text.count("\n", 0, end) + 1
                name = re.search(r"([~\w:]+(?:\s*operator\s*[^\s(]+)?)\s*\(", flat)
                found.append((first_line, last_line, name.group(1) if name else flat[:40]))
                i = end
                header_start = end + 1
            else:  # an initializer or a member's brace-init: skipped whole, header goes on
                i = match_brace(text, i)
        i += 1
    return found


def match_brace(text, i):
    depth = 0
    for j in range(i, len(text)):
        if text[j] == "{":
            depth += 1
        elif text[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(text) - 1


def sources(root):
    for d, dirs, files in os.walk(root):
        rel = os.path.relpath(d, root)
        dirs[:] = sorted(x for x in dirs if x not in SKIP_DIRS and not x.startswith("build") and
                         not os.path.exists(os.path.join(d, x, "CMakeCache.txt")))
        for f in sorted(files):
            if f.endswith(SOURCE_EXT):
                yield os.path.normpath(os.path.join(rel, f))


def main():
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    show_all = "--all" in sys.argv
    root = args[0] if args else "."
    bad = 0
    seen = set()
    for path in sources(root):
        with open(os.path.join(root, path), encoding="utf-8", errors="replace") as f:
            text = blank(f.read())
        for first, last, name in functions(text):
            length = last - first + 1
            if length <= MAX_LINES:
                continue
            short = name.split("::")[-1]
            key = f"{path}:{short}"
            seen.add(key)
            why = ALLOWED.get(key) or REMAINING.get(key)
            if why is None:
                print(f"{path}:{first}: {name} has {length} lines (more than {MAX_LINES})")
                bad = 1
            elif show_all:
                print(f"{path}:{first}: {name} has {length} lines (allowed: {why})")
    for key in sorted(list(ALLOWED) + list(REMAINING)):
        if key not in seen:
            print(f"long_functions: allowlist entry {key} matches no long function; remove it")
            bad = 1
    return bad


if __name__ == "__main__":
    sys.exit(main())
