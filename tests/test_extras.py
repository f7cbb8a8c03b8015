"""The optional extras do not pull a package that pins down what the base installs."""

from __future__ import annotations

import re
from pathlib import Path

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    import tomli as tomllib

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"
#: requirements known to pin a base dependency below what the base installs:
#: ray[rllib] pins gymnasium==1.2.2 (every release through 2.60.0) against the base's gymnasium>=1.0 (1.4)
DOWNGRADING = {"ray": {"rllib"}}


def _project():
    return tomllib.loads(PYPROJECT.read_text())["project"]


def _name_extras(req: str):
    m = re.match(r"\s*([A-Za-z0-9_.-]+)\s*(?:\[([^\]]*)\])?", req)
    return m.group(1).lower().replace("_", "-"), {e.strip() for e in (m.group(2) or "").split(",") if e.strip()}


def test_no_extra_pins_or_caps_a_base_dependency():
    project = _project()
    base = {_name_extras(r)[0] for r in project["dependencies"]}
    for extra, reqs in project["optional-dependencies"].items():
        for req in reqs:
            name, extras = _name_extras(req)
            assert not (DOWNGRADING.get(name, set()) & extras), (
                f"[{extra}] requires {req!r}, which pins a base dependency down (e.g. gymnasium==1.2.2); "
                "list that extra's requirements without the pin")
            if name in base:
                assert not re.search(r"(==|<|~=)", req), f"[{extra}] caps the base dependency {name}: {req!r}"


def test_distributed_extra_keeps_rllibs_requirements():
    reqs = _project()["optional-dependencies"]["distributed"]
    names = {_name_extras(r)[0]: _name_extras(r)[1] for r in reqs}
    assert "tune" in names["ray"]
    for needed in ("dm-tree", "lz4", "ormsgpack", "pyyaml", "torch"):
        assert needed in names, f"[distributed] lacks {needed}, which ray[rllib] needs"
