"""Size figures of the project at a git revision: lines, largest file and function, options.

    python tools/code_stats.py [REV ...]        (default: HEAD; several: one column each)

Reads the files from git (``git ls-tree``, ``git show``), so any commit is measured
without checking it out. Figures: lines in ``docs/`` (text files), ``examples/`` and
``src/``; the largest file and the largest function (lines from ``def`` to its last
line, by `ast`) in ``src/``; the fields of each configuration class in ``src/`` (a
dataclass named ``*Config`` or ``*Options``).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from dataclasses import dataclass, field

TEXT_SUFFIXES = (".md", ".py", ".txt", ".toml", ".csv", ".json", ".html", ".rst")


def _git(*args: str) -> str:
    return subprocess.run(
        ["git", *args], check=True, capture_output=True, text=True, errors="replace"
    ).stdout


@dataclass
class Stats:
    """The figures of one revision."""

    rev: str
    lines: dict[str, int] = field(default_factory=dict)
    largest_file: tuple[int, str] = (0, "")
    largest_function: tuple[int, str] = (0, "")
    options: dict[str, int] = field(default_factory=dict)


def _is_config(node: ast.ClassDef) -> bool:
    named = node.name.endswith(("Config", "Options"))
    decorated = any(
        (isinstance(d, ast.Name) and d.id == "dataclass")
        or (isinstance(d, ast.Call) and getattr(d.func, "id", "") == "dataclass")
        for d in node.decorator_list
    )
    return named and decorated


def measure(rev: str) -> Stats:
    """The figures of ``rev`` (a commit, a branch, ``HEAD``)."""
    stats = Stats(rev)
    files = _git("ls-tree", "-r", "--name-only", rev, "--", "docs", "examples", "src").split()
    for path in files:
        top = path.split("/", 1)[0]
        if not path.endswith(TEXT_SUFFIXES):
            continue
        text = _git("show", f"{rev}:{path}")
        n = text.count("\n")
        stats.lines[top] = stats.lines.get(top, 0) + n
        if top != "src" or not path.endswith(".py"):
            continue
        stats.largest_file = max(stats.largest_file, (n, path))
        tree = ast.parse(text)
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                size = (node.end_lineno or node.lineno) - node.lineno + 1
                stats.largest_function = max(stats.largest_function, (size, f"{path}:{node.name}"))
            elif isinstance(node, ast.ClassDef) and _is_config(node):
                fields = [s for s in node.body if isinstance(s, ast.AnnAssign)]
                stats.options[node.name] = len(fields)
    return stats


def main(revs: list[str]) -> None:
    all_stats = [measure(rev) for rev in revs or ["HEAD"]]
    width = max(12, *(len(s.rev) for s in all_stats))
    print(f"{'':<28}" + "".join(f"{s.rev:>{width}}" for s in all_stats))
    for top in ("docs", "examples", "src"):
        counts = "".join(f"{s.lines.get(top, 0):>{width},}" for s in all_stats)
        print(f"{'lines in ' + top + '/':<28}{counts}")
    for s in all_stats:
        (nf, file), (ng, function) = s.largest_file, s.largest_function
        print(f"{s.rev}: largest file {file} ({nf} lines); largest function {function} ({ng})")
    names = sorted({n for s in all_stats for n in s.options})
    print(f"{'options per config class':<28}" + "".join(f"{s.rev:>{width}}" for s in all_stats))
    for name in names:
        counts = "".join(f"{s.options.get(name, '-'):>{width}}" for s in all_stats)
        print(f"  {name:<26}{counts}")


if __name__ == "__main__":
    main(sys.argv[1:])
