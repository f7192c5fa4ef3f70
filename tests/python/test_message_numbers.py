"""Message numbers: the first digit of every GDT-cnnn names its exit class.

Scans the C and C++ sources for calls that record an error with a literal
status and a literal message number (gdt_error_set, gdt_error_vset, and any
wrapper called as f(..., GDT_Exxx, NNNN, ...)) and checks that the number's
first digit is the class of the status (io/gdt_error.h: the enum values are
the exit codes; GDT_EINTERRUPTED, 130, uses 1xxx).  Calls whose status or
number is not a literal are counted and listed, not checked.
"""
import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
SOURCE_DIRS = ["io", "core", "merge", "tiler", "kernels", "tests/c", "tests/tools"]
SUFFIXES = {".c", ".cpp", ".h", ".hpp"}

# class digit of each status, from io/gdt_error.h
CLASS = {
    "GDT_EUSAGE": "2",
    "GDT_EINPUT": "3",
    "GDT_EIO": "4",
    "GDT_EDEVICE": "5",
    "GDT_EJOB": "6",
    "GDT_EINTERNAL": "7",
    "GDT_EINTERRUPTED": "1",
}
SETTERS = ("gdt_error_set", "gdt_error_vset")


def strip_comments_and_strings(text):
    """The source with comments and string/char literals blanked (newlines
    kept, so offsets map to the same lines)."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif c in "\"'":
            j = i + 1
            while j < n and text[j] != c:
                j += 2 if text[j] == "\\" else 1
            j = min(j + 1, n)
            out.append(c + re.sub(r"[^\n]", " ", text[i + 1:j - 1]) + c)
            i = j
        else:
            out.append(c)
            i += 1
    return "".join(out)


def call_args(text, open_paren):
    """The top-level arguments of the call whose '(' is at open_paren."""
    depth, start, args = 0, open_paren + 1, []
    for j in range(open_paren, len(text)):
        ch = text[j]
        if ch in "([{":
            depth += 1
        elif ch in ")]}":
            depth -= 1
            if depth == 0:
                args.append(text[start:j].strip())
                return args
        elif ch == "," and depth == 1:
            args.append(text[start:j].strip())
            start = j + 1
    return None


def alternatives(expr):
    """The values an argument can take: ['X'] for X, ['A', 'B'] for
    `cond ? A : B` (A and B plain tokens); the whole text otherwise."""
    expr = " ".join(expr.split())
    m = re.fullmatch(r"[^?:]+\?\s*(\w+)\s*:\s*(\w+)", expr)
    return [m.group(1), m.group(2)] if m else [expr]


def scan():
    """(checked, skipped, mismatches): checked is the number of literal
    (status, number) pairs; skipped lists setter calls with a non-literal
    status or number; mismatches lists (where, status, number)."""
    checked, skipped, mismatches = 0, [], []
    files = [p for d in SOURCE_DIRS for p in sorted((ROOT / d).rglob("*"))
             if p.suffix in SUFFIXES and p.is_file()]
    assert files, f"no sources found under {ROOT}"
    for path in files:
        text = strip_comments_and_strings(path.read_text(errors="replace"))
        rel = path.relative_to(ROOT)

        def where(pos):
            return f"{rel}:{text.count(chr(10), 0, pos) + 1}"

        def check(pos, st, code):
            nonlocal checked
            checked += 1
            if st not in CLASS:
                found.add((where(pos), st, code, "unknown status"))
            elif code[0] != CLASS[st]:
                found.add((where(pos), st, code, f"expected {CLASS[st]}xxx"))

        found = set()
        # every setter call, however its arguments are laid out; a status or
        # number chosen by `cond ? a : b` is checked for both branches
        for m in re.finditer(r"\b(%s)\s*\(" % "|".join(SETTERS), text):
            args = call_args(text, m.end() - 1)
            if args is not None and args and "gdt_error *" in args[0]:
                continue  # the declaration or the definition
            if args is None or len(args) < 3:
                skipped.append(f"{where(m.start())}: {m.group(1)} with unreadable arguments")
                continue
            sts, codes = alternatives(args[1]), alternatives(args[2])
            if not all(x in CLASS for x in sts) or \
                    not all(re.fullmatch(r"\d{4}", x) for x in codes) or \
                    (len(sts) > 1 and len(codes) > 1 and len(sts) != len(codes)):
                skipped.append(f"{where(m.start())}: {m.group(1)}(..., {args[1]}, {args[2]}, ...)"
                               .replace("\n", " "))
                continue
            if len(sts) == len(codes):
                pairs = zip(sts, codes)
            else:
                pairs = [(a, b) for a in sts for b in codes]
            for a, b in pairs:
                check(m.start(), a, b)
        # every other call that passes a literal status then a literal number
        # (wrappers that forward to the setters)
        for m in re.finditer(r"\b(GDT_E[A-Z]+)\s*,\s*(\d{4})\b", text):
            check(m.start(), m.group(1), m.group(2))
        mismatches.extend(sorted(found))
    return checked, skipped, mismatches


def test_strip_keeps_code_and_drops_comments():
    src = 'a(/* GDT_EIO, 7001 */ "GDT_EIO, 7001", GDT_EIO, 4001); // GDT_EJOB, 1\n'
    s = strip_comments_and_strings(src)
    assert re.findall(r"(GDT_E[A-Z]+)\s*,\s*(\d{4})", s) == [("GDT_EIO", "4001")]
    assert call_args(s, s.index("("))[1:] == ["GDT_EIO", "4001"]


def test_message_number_matches_status_class():
    checked, skipped, mismatches = scan()
    assert checked > 300, f"only {checked} (status, number) pairs found: the scan is broken"
    print(f"{checked} literal (status, number) pairs checked; {len(skipped)} calls skipped "
          "(status or number not a literal):")
    for s in skipped:
        print("  " + s)
    assert not mismatches, "message numbers whose first digit is not the status class:\n" + \
        "\n".join(f"  {w}: {st}, {code} ({why})" for w, st, code, why in mismatches)
