"""No import cycles in the infrastructure packages (bench, envs, vector, haptics, integrations,
cli, scenarios) nor in the domain packages (geometry, tissue, contact, scene): module A importing B while B imports A, directly or around a
loop, counting imports inside functions too (a lazy import hides a cycle from Python, not from
the reader). Found by an AST scan of every module and Tarjan's strongly connected components of
the import graph."""

import ast
import functools
import pathlib

import pytest

import surgsim_envs

ROOT = pathlib.Path(surgsim_envs.__file__).parent
#: packages whose modules must not sit on an import cycle
PACKAGES = ("bench", "envs", "vector", "haptics", "integrations", "cli", "scenarios", "geometry", "tissue",
            "contact", "scene")


def _module_name(path: pathlib.Path, root: pathlib.Path) -> str:
    parts = ["surgsim_envs", *path.relative_to(root).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(root: pathlib.Path = ROOT) -> dict[str, set[str]]:
    """module -> the package modules it imports (at module level or inside functions). ``from P
    import x`` points at the submodule ``P.x`` when there is one, else at ``P``."""
    files = {_module_name(p, root): p for p in sorted(root.rglob("*.py"))}

    def resolve(name: str) -> str | None:
        while name and name not in files:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for module, path in files.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, ast.Import):
                deps.update(resolve(a.name) for a in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                for a in node.names:
                    sub = files.get(f"{node.module}.{a.name}") and f"{node.module}.{a.name}"
                    deps.add(sub or resolve(node.module))
        deps.discard(None)
        deps.discard(module)
        graph[module] = deps
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan's algorithm, iterative)."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []
    counter = 0
    for start in graph:
        if start in index:
            continue
        work = [(start, iter(sorted(graph[start])))]
        index[start] = low[start] = counter
        counter += 1
        stack.append(start)
        on_stack.add(start)
        while work:
            v, children = work[-1]
            for w in children:
                if w not in graph:
                    continue
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on_stack.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    component = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        component.append(w)
                        if w == v:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return found


def test_cycle_finder_finds_a_loop_of_three_and_ignores_a_chain():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}, "e": set()}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_import_graph_sees_lazy_imports(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "one.py").write_text("def f():\n    from surgsim_envs.pkg import two\n")
    (pkg / "two.py").write_text("import surgsim_envs.pkg.one\n")
    graph = import_graph(tmp_path)
    assert graph["surgsim_envs.pkg.one"] == {"surgsim_envs.pkg.two"}
    assert cycles(graph) == [["surgsim_envs.pkg.one", "surgsim_envs.pkg.two"]]


@functools.lru_cache(maxsize=None)
def package_cycles() -> tuple:
    return tuple(tuple(c) for c in cycles(import_graph()))


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle_touches(package):
    prefix = f"surgsim_envs.{package}"
    bad = [c for c in package_cycles() if any(m == prefix or m.startswith(prefix + ".") for m in c)]
    assert not bad, f"import cycles through {prefix}: {bad}"
