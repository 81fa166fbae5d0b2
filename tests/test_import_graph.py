"""No import circles in ``schemas/``, ``adapters/`` and ``gateway/``, and none hidden by a function-local
import: the module graph is read with ``ast`` (every ``import`` anywhere in a module, in functions too,
except those under ``if TYPE_CHECKING:``, which never run) and must have no cycle.

An edge ``a → b`` means module ``a`` imports module ``b`` (``from pkg import name`` counts as importing
``pkg.name`` when that is a module, else ``pkg``). A package's ``__init__`` is not implied by importing
one of its modules: the graph is of the modules that name each other.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("schemas", "adapters", "gateway")

#: Cycles known and being removed elsewhere, each as the exact set of modules in it. Nothing else may
#: join this list: break the circle instead.
ALLOWED_CYCLES: frozenset[frozenset[str]] = frozenset()


def module_files(root: Path, packages: Iterable[str]) -> dict[str, Path]:
    """Dotted module name → file, for every ``.py`` under the given top-level packages of ``root``."""
    found: dict[str, Path] = {}
    for package in packages:
        for path in sorted((root / package).rglob("*.py")):
            parts = path.relative_to(root).with_suffix("").parts
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found[".".join(parts)] = path
    return found


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _import_nodes(node: ast.AST) -> Iterable[ast.Import | ast.ImportFrom]:
    """Every import statement under ``node``, at any depth, skipping the bodies of ``if TYPE_CHECKING:``
    (their ``else`` branch runs, so it is kept)."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.If) and _is_type_checking(child.test):
            for other in child.orelse:
                yield from _import_nodes_of(other)
            continue
        yield from _import_nodes_of(child)


def _import_nodes_of(node: ast.AST) -> Iterable[ast.Import | ast.ImportFrom]:
    if isinstance(node, ast.Import | ast.ImportFrom):
        yield node
    yield from _import_nodes(node)


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The modules of ``modules`` that module ``name`` (at ``path``) imports."""
    is_package = path.name == "__init__.py"
    found: set[str] = set()
    for node in _import_nodes(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            if node.level:
                package = name.split(".") if is_package else name.split(".")[:-1]
                base = package[: len(package) - (node.level - 1)]
                module = ".".join([*base, node.module] if node.module else base)
            else:
                module = node.module or ""
            targets = [f"{module}.{alias.name}" for alias in node.names]
            targets = [t if t in modules else module for t in targets]
        for target in targets:
            # `import a.b.c` where only a.b is ours still names a.b
            while target and target not in modules:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def import_graph(root: Path, packages: Iterable[str]) -> dict[str, set[str]]:
    modules = module_files(root, packages)
    return {name: imports_of(name, path, modules) for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    found: list[frozenset[str]] = []
    counter = 0
    for start in sorted(graph):
        if start in index:
            continue
        work: list[tuple[str, Iterable[str]]] = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            node, successors = work[-1]
            advanced = False
            for succ in successors:
                if succ not in graph:
                    continue
                if succ not in index:
                    index[succ] = low[succ] = counter
                    counter += 1
                    stack.append(succ)
                    on_stack.add(succ)
                    work.append((succ, iter(sorted(graph[succ]))))
                    advanced = True
                    break
                if succ in on_stack:
                    low[node] = min(low[node], index[succ])
            if advanced:
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                component: set[str] = set()
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.add(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(frozenset(component))
    return found


def _describe(component: frozenset[str], graph: dict[str, set[str]]) -> str:
    edges = sorted(f"{a} → {b}" for a in component for b in graph[a] if b in component)
    return "{" + ", ".join(sorted(component)) + "}: " + "; ".join(edges)


def test_the_packages_have_no_import_cycle() -> None:
    graph = import_graph(ROOT, PACKAGES)
    assert len(graph) > 100, "the walk found too few modules"
    unexpected = [c for c in cycles(graph) if c not in ALLOWED_CYCLES]
    assert unexpected == [], "import cycles:\n" + "\n".join(_describe(c, graph) for c in unexpected)


def test_the_allow_list_names_only_cycles_that_exist() -> None:
    """An allowed cycle that is gone must leave the list (so the list only ever shrinks)."""
    found = set(cycles(import_graph(ROOT, PACKAGES)))
    assert found >= ALLOWED_CYCLES, (
        f"no longer a cycle, delete it: {sorted(map(sorted, ALLOWED_CYCLES - found))}"
    )


#: Service modules that may name the command-line package (none).
CLI_ALIASES: set[str] = set()


def test_the_service_never_imports_the_command_line_front_ends() -> None:
    graph = import_graph(ROOT, PACKAGES)
    front_ends = {name for name in graph if name == "gateway.cli" or name.startswith("gateway.cli.")}
    offenders = sorted(
        f"{name} → {target}"
        for name, targets in graph.items()
        if name not in front_ends and name not in CLI_ALIASES
        for target in targets & front_ends
    )
    assert offenders == []


def _package(tmp_path: Path, files: dict[str, str]) -> dict[str, set[str]]:
    for rel, text in files.items():
        path = tmp_path / rel
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return import_graph(tmp_path, ["toy"])


def test_the_checker_finds_a_cycle_hidden_in_a_function(tmp_path: Path) -> None:
    graph = _package(
        tmp_path,
        {
            "toy/__init__.py": "",
            "toy/a.py": "from toy import b\n",
            "toy/b.py": "def late() -> None:\n    from toy.a import thing\n",
            "toy/c.py": "import toy.b\n",
        },
    )
    assert graph["toy.a"] == {"toy.b"} and graph["toy.b"] == {"toy.a"} and graph["toy.c"] == {"toy.b"}
    assert cycles(graph) == [frozenset({"toy.a", "toy.b"})]


def test_the_checker_follows_relative_and_package_imports(tmp_path: Path) -> None:
    graph = _package(
        tmp_path,
        {
            "toy/__init__.py": "from .sub import x\n",
            "toy/sub/__init__.py": "from . import y\n",
            "toy/sub/y.py": "class C:\n    def m(self) -> None:\n        from .. import sub\n",
            "toy/sub/x.py": "from ..sub.y import C\n",
        },
    )
    assert graph["toy"] == {"toy.sub.x"}
    assert graph["toy.sub"] == {"toy.sub.y"}
    assert graph["toy.sub.y"] == {"toy.sub"}
    assert graph["toy.sub.x"] == {"toy.sub.y"}
    assert cycles(graph) == [frozenset({"toy.sub", "toy.sub.y"})]


def test_the_checker_skips_type_checking_blocks_only(tmp_path: Path) -> None:
    graph = _package(
        tmp_path,
        {
            "toy/__init__.py": "",
            "toy/a.py": "import typing\nfrom toy import b\n",
            "toy/b.py": (
                "from typing import TYPE_CHECKING\n"
                "if TYPE_CHECKING:\n    from toy import a\nelse:\n    from toy import c\n"
                "if typing.TYPE_CHECKING:\n    import toy.a\n"
            ),
            "toy/c.py": "",
        },
    )
    assert graph["toy.b"] == {"toy.c"}
    assert cycles(graph) == []
    # the same import outside the guard is a cycle
    (tmp_path / "toy" / "c.py").write_text("from toy.a import b\n")
    assert cycles(import_graph(tmp_path, ["toy"])) == [frozenset({"toy.a", "toy.b", "toy.c"})]
