"""Package shape: no import cycle, imports only downward, no preset joint names outside skeleton.

The import graph is built from the source with `ast` (nothing is imported), from every
``import`` statement of a module, including those inside functions: an import deferred
into a function still ties the two modules together, it only hides the cycle from the
interpreter.
"""

from __future__ import annotations

import ast
import re
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

import mocapkit

PACKAGE_DIR = Path(mocapkit.__file__).resolve().parent

#: The core layers, lowest first: a package may import only packages before it.
CORE_LAYERS: tuple[str, ...] = (
    "geometry",
    "skeleton",
    "camera",
    "cues",
    "ik",
    "tracking",
    "pipelines",
    "cli",
)
#: Packages beside the core: they build on the core up to `cues` and are used from
#: `pipelines` and `cli`. `io` is the floor of them: synth, eval, viz and detect read and
#: write through it, and import no other side package.
SIDE_PACKAGES: tuple[str, ...] = ("io", "synth", "eval", "viz", "detect")
SIDE_MAY_IMPORT: frozenset[str] = frozenset({"geometry", "skeleton", "camera", "cues"})
#: Core layers that may import the side packages.
CORE_USING_SIDE: frozenset[str] = frozenset({"pipelines", "cli"})

#: Upward imports that are known and being removed, with the branch that removes them.
#: Each entry must still occur: when its import is gone, delete the entry.
KNOWN_UPWARD_IMPORTS: Mapping[tuple[str, str], str] = {}

#: Imports of the top-level package's public face: the library calls it exports on
#: purpose (each with why). Not upward imports to remove.
TOP_LEVEL_EXPORTS: Mapping[tuple[str, str], str] = {
    # issue 16: ``mocapkit.batch(...)`` for notebooks, the library call behind `mocapkit batch`
    ("mocapkit", "mocapkit.pipelines.batch"): "mocapkit.batch",
}

#: A joint name of a preset (zhang21, upper_stick, azad14): generic code finds limbs
#: through `mocapkit.skeleton.limbs` and canonical names instead.
PRESET_JOINT_NAME = re.compile(
    r"\b[lr]_(humerus|radius|hand|femur|tibia|foot|shoulder|elbow|clavicle|hip)\b"
)


# ---------------------------------------------------------------- the graph


def module_files(package_dir: Path) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file under ``package_dir``."""
    root = package_dir.parent
    out: dict[str, Path] = {}
    for path in sorted(package_dir.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _owner(name: str, modules: Mapping[str, Path]) -> str | None:
    """The module (or package) that ``name`` lives in; None outside the package."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def imports_of(module: str, path: Path, modules: Mapping[str, Path]) -> set[str]:
    """Modules of the package that ``module`` imports (anywhere in its source)."""
    is_package = path.name == "__init__.py"
    top = next(iter(modules)).split(".")[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                target = _owner(alias.name, modules)
                if target is not None:
                    out.add(target)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".") if is_package else module.split(".")[:-1]
                base = base[: len(base) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            if name.split(".")[0] != top:
                continue
            for alias in node.names:
                # ``from pkg import sub`` imports the submodule when there is one.
                target = _owner(f"{name}.{alias.name}", modules)
                if target is not None:
                    out.add(target)
    out.discard(module)
    return out


def import_graph(package_dir: Path) -> dict[str, set[str]]:
    """Module -> the package's modules it imports."""
    modules = module_files(package_dir)
    return {m: imports_of(m, p, modules) for m, p in modules.items()}


def find_cycles(graph: Mapping[str, Iterable[str]]) -> list[list[str]]:
    """One cycle (a closed path of modules) per strongly connected group of modules.

    Tarjan's algorithm, iterative; the path is found inside each group by a
    breadth-first search back to its first member.
    """
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    groups: list[list[str]] = []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work: list[tuple[str, Iterator[str]]] = []
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        work.append((start, iter(sorted(graph.get(start, ())))))
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph.get(child, ())))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                group = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    group.append(member)
                    if member == node:
                        break
                if len(group) > 1:
                    groups.append(sorted(group))
    cycles = []
    for group in groups:
        members = set(group)
        first = group[0]
        came_from: dict[str, str] = {}
        frontier = [first]
        while frontier and first not in came_from:
            nxt = []
            for node in frontier:
                for child in sorted(graph.get(node, ())):
                    if child in members and child not in came_from:
                        came_from[child] = node
                        nxt.append(child)
            frontier = nxt
        path = [first]
        node = came_from[first]
        while node != first:
            path.append(node)
            node = came_from[node]
        cycles.append([first, *reversed(path[1:]), first])
    return cycles


def package_of(module: str) -> str:
    """The subpackage a module belongs to; ``""`` for the top-level modules."""
    parts = module.split(".")
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and _is_subpackage(parts[1])) else ""


def _is_subpackage(name: str) -> bool:
    return name in CORE_LAYERS or name in SIDE_PACKAGES


def may_import(src: str, dst: str) -> bool:
    """Whether package ``src`` may import package ``dst`` (``""``: top-level modules)."""
    if src == dst or dst == "":
        return True
    if src == "":
        return False  # errors, progress and the package root stay at the bottom
    if src in CORE_LAYERS and dst in CORE_LAYERS:
        return CORE_LAYERS.index(dst) < CORE_LAYERS.index(src)
    if src in CORE_LAYERS:  # dst is a side package
        return src in CORE_USING_SIDE
    if dst in SIDE_MAY_IMPORT:
        return True
    return dst == "io" and src != "io"


def upward_imports(graph: Mapping[str, Iterable[str]]) -> list[tuple[str, str]]:
    """Every (importer, imported) pair that points upward in the layering."""
    return sorted(
        (m, t)
        for m, targets in graph.items()
        for t in targets
        if not may_import(package_of(m), package_of(t))
    )


def preset_names_in_literals(path: Path) -> list[tuple[int, str]]:
    """(line, literal) of string literals (docstrings aside) holding a preset joint name."""
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    docstrings = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                docstrings.add(id(body[0].value))
    return [
        (node.lineno, node.value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and id(node) not in docstrings
        and PRESET_JOINT_NAME.search(node.value)
    ]


# ---------------------------------------------------------------- the checker itself


def _write(root: Path, files: Mapping[str, str]) -> Path:
    for rel, text in files.items():
        path = root / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
    return root / "fake"


def test_checker_finds_cycles_through_deferred_and_relative_imports(tmp_path: Path) -> None:
    pkg = _write(
        tmp_path,
        {
            "fake/__init__.py": "",
            "fake/io/__init__.py": "",
            "fake/io/a.py": "from fake.io.b import B\n",
            "fake/io/b.py": "def f():\n    from . import c\n",
            "fake/io/c.py": "import fake.io.a\n",
            "fake/io/d.py": "from fake.io import a\nimport numpy\n",
            "fake/io/e.py": "from fake.io.e import x\n",
        },
    )
    graph = import_graph(pkg)
    assert graph["fake.io.b"] == {"fake.io.c"}
    assert graph["fake.io.d"] == {"fake.io.a"}
    assert graph["fake.io.e"] == set()
    assert find_cycles(graph) == [["fake.io.a", "fake.io.b", "fake.io.c", "fake.io.a"]]
    assert find_cycles({"x": {"y"}, "y": set()}) == []


def test_checker_finds_upward_imports(tmp_path: Path) -> None:
    pkg = _write(
        tmp_path,
        {
            "fake/__init__.py": "",
            "fake/errors.py": "",
            "fake/skeleton/__init__.py": "",
            "fake/skeleton/model.py": "from fake.errors import E\nfrom fake.camera import pinhole",
            "fake/camera/__init__.py": "",
            "fake/camera/pinhole.py": "from fake.skeleton.model import S\n",
            "fake/io/__init__.py": "",
            "fake/io/x.py": "from fake.tracking.t import T\nfrom fake.camera.pinhole import C\n",
            "fake/synth/__init__.py": "",
            "fake/synth/s.py": "from fake.io.x import X\nfrom fake.eval.m import M\n",
            "fake/eval/__init__.py": "",
            "fake/eval/m.py": "",
            "fake/tracking/__init__.py": "",
            "fake/tracking/t.py": "from fake.io.x import X\n",
            "fake/pipelines/__init__.py": "",
            "fake/pipelines/p.py": "from fake.synth.s import S\nfrom fake.tracking.t import T\n",
        },
    )
    assert upward_imports(import_graph(pkg)) == [
        ("fake.io.x", "fake.tracking.t"),
        ("fake.skeleton.model", "fake.camera.pinhole"),
        ("fake.synth.s", "fake.eval.m"),
        ("fake.tracking.t", "fake.io.x"),
    ]


def test_checker_finds_preset_names_in_literals_but_not_docstrings(tmp_path: Path) -> None:
    path = tmp_path / "m.py"
    path.write_text(
        '"""Uses l_humerus in prose."""\n'
        "def f():\n"
        '    """r_femur here too."""\n'
        '    return {"arm": "l_humerus", "other": "wall_hand", "key": f"r_foot{1}"}\n',
        encoding="utf-8",
    )
    assert preset_names_in_literals(path) == [(4, "l_humerus"), (4, "r_foot")]


# ---------------------------------------------------------------- the package


def test_no_import_cycles() -> None:
    cycles = find_cycles(import_graph(PACKAGE_DIR))
    assert not cycles, "import cycles (one per group of modules that import each other):\n" + (
        "\n".join(" -> ".join(c) for c in cycles)
    )


def test_imports_point_downward() -> None:
    found = upward_imports(import_graph(PACKAGE_DIR))
    stale = [edge for edge in KNOWN_UPWARD_IMPORTS if edge not in found]
    assert not stale, (
        "known upward imports that no longer occur; delete them from KNOWN_UPWARD_IMPORTS: "
        + ", ".join(f"{a} -> {b}" for a, b in stale)
    )
    new = [edge for edge in found if edge not in KNOWN_UPWARD_IMPORTS]
    new = [edge for edge in new if edge not in TOP_LEVEL_EXPORTS]
    assert not new, "imports pointing upward in the layering:\n" + "\n".join(
        f"{a} imports {b} ({package_of(a) or 'top level'} may not import {package_of(b)})"
        for a, b in new
    )


def test_no_preset_joint_names_outside_skeleton() -> None:
    hits = []
    for module, path in sorted(module_files(PACKAGE_DIR).items()):
        if package_of(module) == "skeleton":
            continue
        for line, literal in preset_names_in_literals(path):
            hits.append(f"{path.relative_to(PACKAGE_DIR.parent)}:{line}: {literal!r}")
    assert not hits, "preset joint names outside mocapkit.skeleton:\n" + "\n".join(hits)
