#!/usr/bin/python3
"""The README is a front door, not a lab notebook (issue 27). Two checks:

  check_readme.py length  ROOT [README]   at most MAX_LINES lines
  check_readme.py figures ROOT [README]   every figure is a quote from the file it cites

A *figure* is a number in the README's prose (code blocks and `code spans` are commands and keys,
not results) that has a decimal point or an exponent (0.8, 1e-7), or a unit, a percent sign or a
times sign after it (200 s, 19 MiB, 3 %, 2.3×). Every figure must appear verbatim (same digits,
same unit) in a repository file cited in the same paragraph, list item or table row, as a
Markdown link or a `path`. So a README line may quote bench/results.md or docs/numerics.md, but
not keep figures of its own: a figure copied from a run the cited file no longer holds, or with
no source beside it, fails here. The few figures that come from the paper itself (outside the
repository) are in ALLOWED. Every repository file the README cites must exist.
"""

import os
import re
import sys

MAX_LINES = 150

# Figures of the paper's specification (../shared/paper, outside the repository) and notation.
ALLOWED = {
    "200 s": "the length of the paper's experiment (Section IV), which scripts/demo runs",
    "2σ": "the ±2σ band Fig. 5 draws: a convention, not a measurement",
}

UNITS = ("%", "×", "x", "ns", "µs", "us", "ms", "s", "min", "h", "Hz", "kHz", "MHz", "B", "KiB",
         "MiB", "GiB", "kB", "MB", "GB", "V", "°C", "K", "req/s", "rad/s", "m/s", "m", "σ")
NUMBER = r"\d+(?:[.,]\d+)*(?:[eE][-−+]?\d+)?"
# A number not glued to a word (θ1, fig2, α1) or to another number; then its unit, if any.
FIGURE = re.compile(r"(?<![\w.,/])(" + NUMBER + r")(?:\s?(" +
                    "|".join(re.escape(u) for u in sorted(UNITS, key=len, reverse=True)) +
                    r")(?![\w/]))?")
# A Markdown link, or a `path` with a folder in it (a bare `paper.yaml` in the layout table names
# a file inside the row's folder, not a source).
CITED = re.compile(r"\]\(([^)#\s]+)(?:#[^)]*)?\)|`([^`\s]*/[^`\s]+\.(?:md|yaml|json|csv|txt|hpp|cpp))`")


def blocks(text):
    """Paragraphs, list items and table rows of the prose, each with its first line number;
    fenced and indented code blocks left out."""
    out, current, start, fenced = [], [], 0, False
    for number, line in enumerate(text.split("\n"), 1):
        if line.startswith("```"):
            fenced = not fenced
            continue
        new_item = re.match(r"\s*([-*] |\|)", line) or line.startswith("#")
        if fenced or not line.strip() or new_item or (line.startswith("    ") and not current):
            if current:
                out.append((start, " ".join(current)))
            current = []
            if fenced or not line.strip() or line.startswith("    "):
                continue
        if not current:
            start = number
        current.append(line.strip())
    if current:
        out.append((start, " ".join(current)))
    return out


def figures(prose):
    """(text, number, unit) of every figure in a block's prose, code spans removed."""
    prose = re.sub(r"`[^`]*`", " ", prose)
    for m in FIGURE.finditer(prose):
        number, unit = m.group(1), m.group(2) or ""
        # "417 / 421 ns", "2 – 3 %": the first number of a pair or range is a figure too.
        paired, pair = False, re.match(r"\s*[/–-]\s*", prose[m.end():])
        if not unit and pair:
            following = FIGURE.match(prose, m.end() + pair.end())
            paired = bool(following and following.group(2))
        measured = unit or paired or re.search(r"[.eE]", number)
        if measured and number.strip("0.,") != "":
            yield (m.group(0), number, unit)


def normalize(text):
    return re.sub(r"[\s\u00a0\u2009\u202f]+", " ", text).replace("−", "-")


def quoted(number, unit, source):
    """Whether `number unit` stands in source as a figure of its own (not the tail of 1.25 or
    the head of 0.81)."""
    pattern = r"(?<![\d.,])" + re.escape(number) + r"(?![\d]|[.,]\d)"
    if unit:
        pattern += r"\s?" + re.escape(unit) + r"(?![\w/])"
    return re.search(pattern, source) is not None


def check_length(root, readme):
    lines = open(readme, encoding="utf-8").read().count("\n")
    if lines > MAX_LINES:
        print(f"FAIL: {os.path.relpath(readme, root)} has {lines} lines, more than {MAX_LINES}: "
              "keep it a front door and move the rest to docs/ or bench/ (docs/README.md lists "
              "where each kind of text lives)")
        return 1
    print(f"{os.path.relpath(readme, root)}: {lines} lines (at most {MAX_LINES})")
    return 0


def check_figures(root, readme):
    text = open(readme, encoding="utf-8").read()
    base = os.path.abspath(root)  # the README sits at the root; its paths are relative to it
    failures, count = [], 0
    for line, prose in blocks(text):
        sources = {}
        for m in CITED.finditer(prose):
            target = m.group(1) or m.group(2)
            if re.match(r"[a-z]+:", target) or target.startswith(("../", "/")):
                continue  # a URL, outside the repository (../shared), or on the installed system
            path = os.path.normpath(os.path.join(base, target))
            if not os.path.exists(path):
                failures.append(f"line {line}: cites {target}, which does not exist")
            elif os.path.isfile(path):
                sources[target] = normalize(open(path, encoding="utf-8", errors="replace").read())
        for shown, number, unit in figures(prose):
            count += 1
            figure = normalize(f"{number} {unit}" if unit else number)
            if figure in ALLOWED or normalize(shown) in ALLOWED:
                continue
            if any(quoted(normalize(number), unit, s) for s in sources.values()):
                continue
            where = (f"none of {', '.join(sorted(sources))} has it" if sources
                     else "no file is cited beside it")
            failures.append(f"line {line}: '{shown}' is not a quote ({where})")
    for f in failures:
        print("FAIL: " + f)
    if failures:
        print(f"{len(failures)} problem(s): a figure in README.md must be a verbatim quote from a "
              "file cited in the same paragraph, list item or table row (bench/results.md for the "
              "benchmarks, bench/montecarlo.md, docs/numerics.md); better still, link and quote "
              "nothing")
        return 1
    print(f"{os.path.relpath(readme, root)}: {count} figure(s), each quoted from the file beside it")
    return 0


def main(argv):
    if len(argv) not in (3, 4) or argv[1] not in ("length", "figures"):
        print(__doc__)
        return 64
    root = argv[2]
    readme = argv[3] if len(argv) == 4 else os.path.join(root, "README.md")
    return (check_length if argv[1] == "length" else check_figures)(root, readme)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
