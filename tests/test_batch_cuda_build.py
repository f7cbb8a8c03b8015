"""The batched backend's kernels build for CUDA GPUs on a host without one (Warp's NVRTC), and the
cubin reader reports registers and local memory correctly (surgsim_envs/batch/cuda_build.py,
cubin_info.py)."""

from __future__ import annotations

import struct

import pytest

from surgsim_envs.batch.cubin_info import CubinError, kernel_resources, occupancy
from surgsim_envs.batch.cuda_build import KERNEL_MODULES, SUBSTEP_KERNELS, check_archs, kernel_name
from surgsim_envs.errors import ConfigError

#: compiled in the slow run only: its reward kernel takes ~20 s in NVRTC
SLOW_MODULES = ("surgsim_envs.batch.palpation_kernels",)


def _nvrtc():
    """(warp, cuda_build) or skip with the reason this host cannot build CUDA code."""
    from surgsim_envs.batch import backend, cuda_build

    if not backend.available():
        pytest.skip("the batched backend's packages are missing (pip install -e '.[batch]')")
    reason = cuda_build.cuda_build_unavailable(90)
    if reason is not None:
        pytest.skip(reason)
    wp, _ = backend.require()
    return wp, cuda_build


def test_occupancy_follows_the_register_limit():
    # 256-thread blocks (8 warps) on sm_90: 65,536 registers, 64 warps, registers allocated per warp in 256s
    assert occupancy(32) == 1.0           # 8 blocks x 8 warps
    assert occupancy(40) == 0.75          # 1,280 per warp -> 6 blocks
    assert occupancy(64) == 0.5
    assert occupancy(96) == 0.25
    assert occupancy(128) == 0.25
    assert occupancy(166) == 0.125        # 5,376 per warp -> 1 block
    assert occupancy(255) == 0.125
    assert occupancy(33) == 0.75          # 33 x 32 = 1,056 rounds up to 1,280
    # sm_89 holds 48 warps: 6 blocks of 8 at 32 registers fill it, 4 blocks at 64 fill two thirds
    assert occupancy(32, arch=89) == 1.0
    assert occupancy(64, arch=89) == pytest.approx(2 / 3)
    # 1,024-thread blocks: one block of 32 warps at 64 registers (65,536) is half of sm_90
    assert occupancy(64, block_dim=1024) == 0.5
    assert occupancy(65, block_dim=1024) == 0.0


@pytest.mark.parametrize("registers, block_dim", [(0, 256), (256, 256), (32, 0), (32, 2048)])
def test_occupancy_refuses_impossible_kernels(registers, block_dim):
    with pytest.raises(ValueError, match="registers|block"):
        occupancy(registers, block_dim)


def test_kernel_names_and_archs():
    assert kernel_name("contact_points_e360b0fd_cuda_kernel_forward") == "contact_points"
    assert kernel_name("contact_points_e360b0fd_cuda_kernel_backward") is None
    assert kernel_name("$evaluate_step_014de76a_cuda_kernel_forward$__internal_accurate_pow") is None
    assert check_archs([90, 80, 90]) == (90, 80)
    for bad in ([20], [True], ["90"], []):
        with pytest.raises(ConfigError, match="arch|architecture"):
            check_archs(bad)


def test_cubin_reader_refuses_other_files(tmp_path):
    text = tmp_path / "not.cubin"
    text.write_text("not an ELF file")
    with pytest.raises(CubinError, match="ELF"):
        kernel_resources(text)
    cut = tmp_path / "cut.cubin"
    cut.write_bytes(b"\x7fELF" + bytes([2]) + b"\0" * 40 + struct.pack("<Q", 10 ** 6))
    with pytest.raises(CubinError, match="truncated|malformed"):
        kernel_resources(cut)


def test_cubin_reader_sees_registers_and_local_memory(tmp_path):
    """A kernel that reads a local array at a runtime index must keep that array in local memory; a
    one-line kernel needs a handful of registers and none."""
    wp, _ = _nvrtc()
    vec32 = wp.types.vector(length=32, dtype=wp.float64)

    @wp.kernel(name="scale", module="unique", enable_backward=False)
    def scale(x: wp.array(dtype=wp.float64)):
        i = wp.tid()
        x[i] = x[i] * wp.float64(2.0)

    @wp.kernel(name="pick", module="unique", enable_backward=False)
    def pick(x: wp.array(dtype=wp.float64), k: wp.array(dtype=wp.int32)):
        i = wp.tid()
        v = vec32()
        for j in range(32):
            v[j] = x[i] * wp.float64(j)
        x[i] = v[k[i]]

    found = {}
    for kern in (scale, pick):
        path = [p for p in wp.compile_aot_module(kern.module, arch=90, module_dir=str(tmp_path), use_ptx=False)
                if str(p).endswith(".cubin")][0]
        (res,) = kernel_resources(path)
        found[kernel_name(res.symbol)] = res
    assert found["scale"].local_bytes == 0 and 4 <= found["scale"].registers <= 32
    assert found["pick"].local_bytes >= 32 * 8                 # the 32 doubles it indexes at run time


def _check_modules(cuda_build, modules, arch, tmp_path):
    import importlib

    wp, _ = _nvrtc()
    reports, seconds = cuda_build.build((arch,), out_dir=tmp_path, modules=modules)
    assert set(seconds) == {f"{m}@sm_{arch}" for m in modules}
    for name in modules:
        importlib.import_module(name)
        own = {r.kernel: r for r in reports if r.module == name}
        assert set(own) == set(wp.get_module(name).kernels), name          # every kernel built, nothing else
        for r in own.values():
            assert 1 <= r.registers <= 255 and 0 < r.occupancy <= 1
            if r.kernel in SUBSTEP_KERNELS.get(name, ()):
                # the physics substep keeps its state in registers: no spills to local memory
                assert r.local_bytes == 0, (name, r)
    for name, kernels in SUBSTEP_KERNELS.items():
        if name in modules:     # every substep kernel named exists and is marked as such
            assert set(kernels) == {r.kernel for r in reports if r.module == name and r.substep}, name


def test_backend_kernels_build_for_hopper(tmp_path):
    """Every kernel module but the palpation rewards builds for sm_90 (H100, H200) through NVRTC,
    and no kernel of the physics substep spills."""
    _, cuda_build = _nvrtc()
    _check_modules(cuda_build, tuple(m for m in KERNEL_MODULES if m not in SLOW_MODULES), 90, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("arch", [90, 80])
def test_every_backend_kernel_builds(arch, tmp_path):
    _, cuda_build = _nvrtc()
    _check_modules(cuda_build, KERNEL_MODULES, arch, tmp_path)


def test_cli_refuses_a_bad_arch(capsys):
    from surgsim_envs.cli import main

    assert main(["bench", "cuda-build", "--arch", "sm_9x"]) == 2
    assert "--arch entry '9x'" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_writes_the_report(tmp_path):
    import json

    _nvrtc()
    from surgsim_envs.cli import main

    assert main(["bench", "cuda-build", "--arch", "90", "--json", "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "cuda_build.json").read_text())
    kernels = {(k["module"].rsplit(".", 1)[-1], k["kernel"]) for k in data["kernels"]}
    assert ("contact_kernels", "contact_points") in kernels and ("palpation_kernels", "evaluate_step") in kernels
    assert "| contact_kernels | contact_points | sm_90 | yes |" in (tmp_path / "cuda_build.md").read_text()


def test_cli_names_what_is_missing(monkeypatch, capsys):
    """Without the [batch] extra (or without NVRTC) the command exits 2 with the reason, no traceback."""
    from surgsim_envs.batch import backend, cuda_build
    from surgsim_envs.cli import main

    def missing():
        raise backend.BatchUnavailableError(f"the batched backend needs NVIDIA Warp (warp-lang): test; {backend.INSTALL_HINT}")

    monkeypatch.setattr(backend, "require", missing)
    assert cuda_build.cuda_build_unavailable(90).startswith("the batched backend needs NVIDIA Warp")
    assert main(["bench", "cuda-build", "--arch", "90"]) == 2
    err = capsys.readouterr().err
    assert "needs NVIDIA Warp" in err and "pip install" in err
