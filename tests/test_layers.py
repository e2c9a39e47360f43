"""The package's layers run one way, and no import inside a function dodges a cycle.

Every module of ``liesample`` belongs to the layer of the folder it sits in (the order is
declared below, by folder; top-level modules are the public face); an import
(at the top of a module or inside a function) may only point to the same layer or a lower
one. On top of that, the whole import graph — top-level and function-level imports together,
with the edge from a sub-package's module to that sub-package's ``__init__`` that Python runs
first — must be acyclic, so a function-level import is never a way round a cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "liesample"

# Lowest first: each layer is a set of sub-packages (folders) of ``liesample``; a module's layer
# is that of the folder it sits in. Modules at the top level (the package ``__init__``, ``cli``,
# the NumPyro entry points) are the public face, above everything.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("foundation", ("foundation",)),
    ("geometry / targets", ("geometry", "targets")),
    ("dynamics", ("dynamics",)),
    ("integrators", ("integrators",)),
    ("systems", ("systems",)),
    ("samplers", ("samplers",)),
    ("tuning", ("tuning",)),
    ("run / analysis / interop", ("run", "analysis", "interop")),
)
PUBLIC_FACE = ("public face", ())


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}


def layer_of(module: str) -> int | None:
    """The index of ``module``'s layer: its folder's, or the public face for top-level modules."""
    parts = module.split(".")
    if parts[0] != "liesample" or module not in MODULES:
        return None
    if (len(parts) == 2 and MODULES[module].name != "__init__.py") or module == "liesample":
        return len(LAYERS)
    for index, (_, folders) in enumerate(LAYERS):
        if parts[1] in folders:
            return index
    return None


def layer_name(index: int) -> str:
    return (LAYERS + (PUBLIC_FACE,))[index][0]


def _resolve(node: ast.ImportFrom, module: str) -> str:
    if not node.level:
        return node.module or ""
    package = module if MODULES[module].name == "__init__.py" else module.rsplit(".", 1)[0]
    base = package.split(".")
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def imports_of(module: str) -> list[tuple[str, int, bool]]:
    """``(imported liesample module, line, inside a function)`` for every import in ``module``."""
    tree = ast.parse(MODULES[module].read_text(), filename=str(MODULES[module]))
    found = []

    def visit(node, in_function):
        for child in ast.iter_child_nodes(node):
            nested = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef)
            if isinstance(child, ast.If) and _is_type_checking(child.test):
                nested = True  # typing-only: counts like a deferred import
            if isinstance(child, ast.Import):
                targets = [alias.name for alias in child.names]
            elif isinstance(child, ast.ImportFrom):
                source = _resolve(child, module)
                # ``from pkg import sub`` imports the sub-module ``pkg.sub`` when there is one.
                targets = [
                    f"{source}.{alias.name}" if f"{source}.{alias.name}" in MODULES else source
                    for alias in child.names
                ]
            else:
                visit(child, nested)
                continue
            for target in targets:
                if target == "liesample" or target.startswith("liesample."):
                    found.append((_known_module(target), child.lineno, nested))
            visit(child, nested)

    visit(tree, False)
    return found


def _is_type_checking(test) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _known_module(name: str) -> str:
    while name not in MODULES and "." in name:
        name = name.rsplit(".", 1)[0]
    return name


def _edges(module: str) -> set[str]:
    """What importing ``module`` runs: its imports and, for a module of another package, the
    ``__init__`` of each sub-package enclosing it (Python runs that first). The root package and
    the packages enclosing ``module`` itself are already being imported, so they add nothing."""
    own = module if MODULES[module].name == "__init__.py" else module.rsplit(".", 1)[0]
    edges = set()
    for target, _, _ in imports_of(module):
        edges.add(target)
        parts = target.split(".")
        for depth in range(2, len(parts)):
            package = ".".join(parts[:depth])
            if not (own == package or own.startswith(package + ".")):
                edges.add(package)
    edges.discard(module)
    return edges - ({"liesample"} if module != "liesample" else set())


def test_every_module_has_a_layer():
    missing = sorted(module for module in MODULES if layer_of(module) is None)
    assert not missing, f"{missing} sit in no layer folder (tests/test_layers.py::LAYERS)"


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_point_down_or_across(module):
    layer = layer_of(module)
    if layer is None:
        pytest.skip("no layer declared (test_every_module_has_a_layer fails)")
    upward = [
        f"line {line}: {target} ({layer_name(layer_of(target))}) from {layer_name(layer)}"
        + (" inside a function" if nested else "")
        for target, line, nested in imports_of(module)
        if layer_of(target) is not None and layer_of(target) > layer
    ]
    assert not upward, f"{module} imports upward: " + "; ".join(upward)


def test_the_import_graph_has_no_cycle():
    """Top-level and function-level imports together: a deferred import may not close a loop."""
    graph = {module: _edges(module) & MODULES.keys() for module in MODULES}
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(module):
        state[module] = 1
        path.append(module)
        for target in sorted(graph[module]):
            if state.get(target) == 1:
                loop = path[path.index(target) :] + [target]
                pytest.fail("import cycle: " + " -> ".join(loop))
            if target not in state:
                visit(target)
        path.pop()
        state[module] = 2

    for module in sorted(graph):
        if module not in state:
            visit(module)


def test_the_checker_sees_function_level_and_upward_imports(tmp_path, monkeypatch):
    """The checks can fail: an upward import inside a function is found and flagged."""
    fake = tmp_path / "liesample"
    (fake / "systems").mkdir(parents=True)
    (fake / "dynamics").mkdir(parents=True)
    (fake / "__init__.py").write_text("")
    (fake / "dynamics" / "__init__.py").write_text("")
    (fake / "dynamics" / "core.py").write_text(
        "def f():\n    from liesample.systems.point_vortices import x\n"
    )
    (fake / "systems" / "__init__.py").write_text("from liesample.systems import point_vortices\n")
    (fake / "systems" / "point_vortices.py").write_text("from liesample.dynamics.core import f\n")
    monkeypatch.setitem(globals(), "PACKAGE", fake)
    monkeypatch.setitem(
        globals(), "MODULES", {module_name(p): p for p in sorted(fake.rglob("*.py"))}
    )
    assert imports_of("liesample.dynamics.core") == [("liesample.systems.point_vortices", 2, True)]
    with pytest.raises(AssertionError, match="imports upward"):
        test_imports_point_down_or_across("liesample.dynamics.core")
    with pytest.raises(pytest.fail.Exception, match="import cycle"):
        test_the_import_graph_has_no_cycle()
