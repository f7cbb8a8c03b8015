"""Dependencies point one way (DESIGN.md): every module's imports, found by an AST scan (lazy
imports inside functions included), go only to layers below its own."""

import ast
import pathlib
import subprocess
import sys

import pytest

import surgsim_envs

ROOT = pathlib.Path(surgsim_envs.__file__).parent
#: layer rank: a module may import only packages of a strictly lower rank (plus its own package)
RANK = {"errors": 0, "after_import": 0, "numba_cache_lock": 0.05, "numba_cache": 0.1, "validate": 0.25, "materials": 0.5, "asset_files": 1, "policies": 1, "geometry": 1, "contact_law": 1.5, "tissue": 2, "contact": 2, "scene": 3, "envs": 4, "haptics": 4,
        "planning": 3, "scenarios": 5, "bench": 5, "integrations": 4.5, "cli": 6}
RANK["warmup"] = 5          # `surgsim warmup`: exercises the demo (scene) and the tasks (envs)
RANK["vector"] = 3.5         # the vector env: steps envs made by gymnasium.make, imports no task
RANK["batch"] = 4.5         # the batched Warp backend: sits on scene and on the tasks (their configs and terms)
#: third-party packages a layer must not import
FORBIDDEN = {"tissue": {"mujoco", "gymnasium"}, "contact_law": {"mujoco", "gymnasium"}, "geometry": {"mujoco", "gymnasium"},
             "contact": {"mujoco", "gymnasium"}}


def _imports(path: pathlib.Path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, node.lineno
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module, node.lineno
        elif isinstance(node, ast.ImportFrom) and node.level > 0:
            raise AssertionError(f"{path}:{node.lineno}: relative import; use absolute surgsim_envs.* imports")


def _modules():
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT)
        if len(rel.parts) == 1 and rel.stem == "__init__":
            continue   # the package root (checked by the subprocess test below)
        yield path, rel.parts[0] if len(rel.parts) > 1 else rel.stem


def test_every_module_has_a_layer():
    missing = sorted({layer for _, layer in _modules()} - set(RANK))
    assert not missing, f"packages without a layer rank in tests/test_layering.py: {missing}"


@pytest.mark.parametrize("layer", sorted(RANK))
def test_no_module_imports_a_layer_above_it(layer):
    bad = []
    for path, own in _modules():
        if own != layer:
            continue
        for module, line in _imports(path):
            top = module.split(".")[0]
            if top in FORBIDDEN.get(own, ()):
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
            if top == "surgsim_envs" and module != "surgsim_envs":
                target = module.split(".")[1]
                if target != own and RANK.get(target, 99) >= RANK[own]:
                    bad.append(f"{path.relative_to(ROOT)}:{line} imports {module} (layer {target} is not below {own})")
    assert not bad, "\n".join(bad)


def test_import_tissue_loads_neither_gymnasium_nor_mujoco():
    code = ("import sys, surgsim_envs.tissue, surgsim_envs.geometry, surgsim_envs.contact; "
            "print(sorted(m for m in ('gymnasium', 'mujoco', 'surgsim_envs.scene', 'surgsim_envs.envs') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout + out.stderr


def test_tasks_still_register_when_gymnasium_is_imported_after_the_package():
    code = ("import surgsim_envs.tissue, gymnasium as gym; "
            "print('SurgSim/Palpation-v0' in gym.registry)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "True", out.stdout + out.stderr


def test_no_tissue_module_reads_files_of_a_layer_above():
    # tissue/resolution.py used to read bench/data/accuracy_table.json
    for path in sorted((ROOT / "tissue").rglob("*.py")):
        text = path.read_text()
        for layer in ("bench", "scene", "envs", "scenarios", "haptics"):
            assert f'"{layer}", "data"' not in text and f"{layer}/data" not in text, f"{path} reads {layer}/"
