"""A reference solve too large for the host is refused with the figures and the fix, before it
starts, instead of being killed by the kernel's out-of-memory killer."""

import pytest

from surgsim_envs.bench import layered_reference, memory_need
from surgsim_envs.bench import task_accuracy as ta
from surgsim_envs.bench.probe_set import ProbeSet
from surgsim_envs.bench.probe_sets import layered_palpation as lp
from surgsim_envs.errors import ConfigError


def _meminfo(tmp_path, available_kb):
    path = tmp_path / "meminfo"
    path.write_text(f"MemTotal:       24000000 kB\nMemFree:         1000000 kB\nMemAvailable:   {available_kb} kB\n")
    return path


def test_available_memory_is_read_from_meminfo_and_unknown_without_it(tmp_path):
    assert memory_need.available_bytes(_meminfo(tmp_path, 2_000_000)) == 2_000_000 * 1024.0
    assert memory_need.available_bytes(tmp_path / "missing") is None
    (tmp_path / "other").write_text("MemTotal: 1000 kB\n")
    assert memory_need.available_bytes(tmp_path / "other") is None


def test_a_need_above_the_available_memory_is_refused_with_both_figures_and_the_fix(tmp_path):
    path = _meminfo(tmp_path, 4_000_000)                       # 4.1 GB
    memory_need.require_memory(3e9, "a solve", "do less", meminfo=path)
    with pytest.raises(ConfigError, match=r"a solve needs about 5\.0 GB of memory; this host has 4\.1 GB available\. "
                                          r"do less"):
        memory_need.require_memory(5e9, "a solve", "do less", meminfo=path)
    memory_need.require_memory(1e15, "a solve", "do less", meminfo=tmp_path / "missing")   # unknown: not checked


def test_the_layered_reference_peak_follows_its_measured_points():
    (n0, m0), (n1, m1) = layered_reference.PEAK_MEMORY
    assert layered_reference.peak_memory(n0) == pytest.approx(m0, rel=1e-12)
    assert layered_reference.peak_memory(n1) == pytest.approx(m1, rel=1e-12)
    assert layered_reference.peak_memory(48_300) == pytest.approx(6.3e9, rel=0.05)     # the 1 mm level


def test_layered_palpation_reference_is_refused_before_any_level_runs(tmp_path, monkeypatch):
    monkeypatch.setattr(memory_need, "MEMINFO", _meminfo(tmp_path, 1_000))              # 1 MB available

    def solve(*args, **kwargs):
        raise AssertionError("a reference level ran although the finest cannot fit")

    monkeypatch.setattr(lp, "reference_row", solve)
    probes = ProbeSet(inclusions=lp.FULL.inclusions, depths=(0.0045,), hold=0.0, spacings=(0.01,),
                      reference_spacings=(0.008, 0.004))
    with pytest.raises(ConfigError, match=r"SurgSim/LayeredPalpation-v0: the reference at fine spacing 4 mm "
                                          r"\(\d+ nodes at the over site\) needs about .* GB of memory; this host has "
                                          r"0\.0 GB available\. Run the quick set"):
        ta.converged_reference(lp.TASK, probes, progress=lambda _: None)


def test_each_press_site_is_checked_before_its_solve(tmp_path, monkeypatch):
    monkeypatch.setattr(memory_need, "MEMINFO", _meminfo(tmp_path, 1_000))
    monkeypatch.setattr(layered_reference, "site_forces",
                        lambda *a, **k: (_ for _ in ()).throw(AssertionError("solved without the check")))
    with pytest.raises(ConfigError, match=r"fine spacing 4 mm \(\d+ nodes at the mirror site\) needs about"):
        lp.reference_row(lp.TASK, lp.FULL, 0.004, sites=("mirror",))
