"""No import cycles: the module-level imports of the package's modules (found by an AST scan; imports
inside functions are deferred on purpose and not counted) form no cycle through a module of the
package checked. A cycle makes the import order matter and hides which module is the base of which."""

import ast
import functools
import pathlib

import pytest

import surgsim_envs

ROOT = pathlib.Path(surgsim_envs.__file__).parent


def _module_name(path: pathlib.Path) -> str:
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _is_type_checking(node) -> bool:
    return isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test)


def _top_level_imports(tree: ast.Module, deferred: bool = False):
    """Import statements executed when the module is imported: the module body, descending into
    ``if`` / ``try`` / ``with`` blocks but not into functions or classes (``deferred``: into those
    too, i.e. every import that can run). ``if TYPE_CHECKING:`` blocks never run."""
    stack = list(tree.body)
    while stack:
        node = stack.pop()
        if _is_type_checking(node):
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node
        elif deferred and isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef, ast.For,
                                            ast.While)):
            stack.extend(node.body)
        elif isinstance(node, (ast.If, ast.Try, ast.With)):
            for field in ("body", "orelse", "finalbody", "handlers"):
                stack.extend(getattr(node, field, []))
        elif isinstance(node, ast.ExceptHandler):
            stack.extend(node.body)


@functools.lru_cache(maxsize=2)
def import_graph(deferred: bool = False) -> dict[str, set[str]]:
    """{module: modules of surgsim_envs it imports at module level (``deferred``: anywhere)};
    ``from a import b`` names the submodule ``a.b`` when there is one, else the module ``a``."""
    paths = sorted(ROOT.rglob("*.py"))
    modules = {_module_name(p) for p in paths}
    graph = {}
    for path in paths:
        deps = set()
        for node in _top_level_imports(ast.parse(path.read_text(), filename=str(path)), deferred):
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif node.module:
                names = [f"{node.module}.{a.name}" if f"{node.module}.{a.name}" in modules else node.module
                         for a in node.names]
            else:
                names = []
            deps.update(n for n in names if n in modules)
        graph[_module_name(path)] = deps
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), and modules importing
    themselves, each sorted."""
    index, low, on_stack, stack, out = {}, {}, set(), [], []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph.get(v, ()):
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_cycle_finder_finds_a_cycle_and_accepts_a_chain():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []
    assert cycles({"a": {"a"}}) == [["a"]]


@pytest.mark.parametrize("package", ["scene", "envs", "bench"])
def test_no_import_cycle_in_package(package):
    prefix = f"surgsim_envs.{package}"
    found = [c for c in cycles(import_graph()) if any(m == prefix or m.startswith(prefix + ".") for m in c)]
    assert not found, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_the_step_is_not_in_a_cycle_even_through_deferred_imports():
    """The physics step (scene/step/, scene/simulation.py, the tissue's compiled-step ABI) takes part in
    no cycle even counting imports inside functions: nothing there imports a module lazily to dodge
    one."""
    step = ("surgsim_envs.scene.step", "surgsim_envs.scene.simulation", "surgsim_envs.tissue.compiled")
    found = [c for c in cycles(import_graph(deferred=True)) if any(m.startswith(step) for m in c)]
    assert not found, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in found)
