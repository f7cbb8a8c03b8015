"""No module reads another package's underscore attributes (as tests/test_layering.py enforces the
layers): what a package keeps private may change without notice to the others.

Found by an AST scan of every module of ``surgsim_envs``:

(a) ``from surgsim_envs.<other package>... import _name`` (or through a private module);
(b) ``obj._name`` and ``getattr/hasattr/setattr(obj, "_name")`` with ``obj`` not ``self``/``cls``
    (dunders allowed), where ``_name`` is not defined in the reader's own package (a def, a class,
    a module, a name assigned, a parameter, or an attribute assigned, ``self._name = ...`` or
    ``obj._name = ...``: a package's own scratch on its own objects): then it
    is another package's private, or a third-party library's.

A package is a folder under ``surgsim_envs/`` (``tissue``, ``scene``, ...) or a top-level module.
"""

import ast
import collections
import functools
import pathlib

import surgsim_envs

ROOT = pathlib.Path(surgsim_envs.__file__).parent

#: (file, name) reads kept on purpose, with the reason; each must still occur
ALLOWED = {
    ("vector/parent.py", "_exit"): "os._exit: the standard library's documented exit without cleanup (a forked worker)",
    ("vector/worker.py", "_exit"): "os._exit: the standard library's documented exit without cleanup (a forked worker)",
    ("scene/step/mujoco_native.py", "_address"): "MuJoCo's bindings expose the mjModel*/mjData* pointers only as "
                                                 "_address; the compiled loop calls mj_step1/mj_step2 through them",
    ("bench/envs_speed.py", "_add_info"): "Gymnasium's VectorEnv._add_info is the info merge this benchmark times "
                                          "(SurgSimVectorEnv, a VectorEnv subclass, calls it as self._add_info)",
}

#: reads of other packages' privates not yet replaced by a public interface. This set must shrink
#: to empty; the test fails on any read not listed here and on any entry that no longer occurs, so
#: a fixed read must also leave this set.
KNOWN_VIOLATIONS: set = set()


def _private(name: str) -> bool:
    return name.startswith("_") and not (name.startswith("__") and name.endswith("__"))


def _package(path: pathlib.Path) -> str:
    rel = path.relative_to(ROOT)
    return rel.parts[0] if len(rel.parts) > 1 else rel.stem


def _is_self(node: ast.AST) -> bool:
    return isinstance(node, ast.Name) and node.id in ("self", "cls")


def _string_attribute(node: ast.AST):
    """(obj, "_name") of ``getattr(obj, "_name", ...)`` / ``hasattr`` / ``setattr``, else None."""
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
            and node.func.id in ("getattr", "hasattr", "setattr") and len(node.args) >= 2
            and isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str)):
        return node.args[0], node.args[1].value
    return None


def definitions(trees: dict) -> dict[str, set[str]]:
    """package -> the private names it defines."""
    out = collections.defaultdict(set)
    for path, tree in trees.items():
        names = out[_package(path)]
        if _private(path.stem):
            names.add(path.stem)
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                names.add(node.name)
            elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
                names.add(node.id)
            elif isinstance(node, ast.arg):
                names.add(node.arg)
            elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
                names.add(node.attr)      # self._x = ..., or obj._x = ... on the package's own objects
            elif (pair := _string_attribute(node)) and node.func.id == "setattr":
                names.add(pair[1])
    return out


def violations(trees: dict) -> dict[tuple[str, str], list[int]]:
    """(file relative to the package root, private name) -> lines where another package's is read."""
    defined = definitions(trees)
    found = collections.defaultdict(list)
    for path, tree in trees.items():
        own = _package(path)
        rel = path.relative_to(ROOT).as_posix()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("surgsim_envs."):
                parts = node.module.split(".")
                if parts[1] == own:
                    continue
                for alias in node.names:
                    for name in (alias.name, *parts[1:]):
                        if _private(name):
                            found[(rel, name)].append(node.lineno)
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    parts = alias.name.split(".")
                    if parts[0] == "surgsim_envs" and len(parts) > 1 and parts[1] != own:
                        for name in parts[1:]:
                            if _private(name):
                                found[(rel, name)].append(node.lineno)
            else:
                if isinstance(node, ast.Attribute):
                    obj, name = node.value, node.attr
                elif pair := _string_attribute(node):
                    obj, name = pair
                else:
                    continue
                if _private(name) and not _is_self(obj) and name not in defined[own]:
                    found[(rel, name)].append(node.lineno)
    return found


@functools.lru_cache(maxsize=None)
def package_violations() -> dict:
    trees = {p: ast.parse(p.read_text(), filename=str(p)) for p in sorted(ROOT.rglob("*.py"))}
    return dict(violations(trees))


def _scan(files: dict[str, str]) -> set:
    """Violations of a throw-away package laid out like ROOT (for testing the scanner itself)."""
    trees = {}
    for rel, text in files.items():
        path = ROOT / rel                # only the path's shape is used; nothing is written there
        trees[path] = ast.parse(text)
    return set(violations(trees))


def test_scanner_flags_reads_of_another_packages_privates():
    found = _scan({
        "aaa/model.py": "class M:\n    def __init__(self):\n        self._state = 1\n        self.public = 2\n",
        "aaa/user.py": "def f(m):\n    return m._state\n",                       # same package: fine
        "bbb/reader.py": ("from surgsim_envs.aaa.model import _helper\n"
                          "def g(m):\n    return m._state + m.public + getattr(m, '_other', 0) + m.__dict__.get('x')\n"),
        "bbb/own.py": "class N:\n    def __init__(self):\n        self._mine = 0\n\ndef h(n):\n    return n._mine\n",
    })
    assert found == {("bbb/reader.py", "_helper"), ("bbb/reader.py", "_state"), ("bbb/reader.py", "_other")}


def test_no_module_reads_another_packages_private_attributes():
    found = package_violations()
    new = sorted(k for k in found if k not in KNOWN_VIOLATIONS and k not in ALLOWED)
    assert not new, "reads of another package's (or library's) private names, with lines:\n" + "\n".join(
        f"  {f}: {name} (lines {found[(f, name)]})" for f, name in new)


def test_known_violations_and_allowances_still_occur():
    """A read that was fixed must leave KNOWN_VIOLATIONS (so the set only shrinks), and an
    allowance whose read is gone must leave ALLOWED."""
    found = package_violations()
    stale = sorted((KNOWN_VIOLATIONS | set(ALLOWED)) - set(found))
    assert not stale, f"entries in tests/test_private_access.py that no longer occur; delete them: {stale}"
    assert not KNOWN_VIOLATIONS & set(ALLOWED)
