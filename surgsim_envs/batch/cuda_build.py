"""Build the batched backend's Warp kernels for CUDA GPUs on any host, and state what they cost an SM.

Warp's wheel carries NVIDIA's runtime compiler (NVRTC), so ``wp.compile_aot_module`` builds a
module's CUDA binary (cubin) for a named GPU architecture on a machine with no GPU and no driver.
:func:`build` does that for every kernel module of the backend (:data:`KERNEL_MODULES`) and reads
each kernel's registers and local memory per thread from the binary (:mod:`cubin_info`), with the
occupancy those registers allow at Warp's default 256-thread blocks. It answers, before a GPU is
rented or on CI without one:

* does every kernel compile for CUDA (CUDA-only code paths, float64 atomics, sizes of local state)?
* does any kernel of the physics substep spill registers to local memory (a slow path on a GPU)?
* how much of an SM can each kernel fill?

It cannot give run times: occupancy bounds how well a kernel hides memory latency, not its speed.
MuJoCo Warp's own kernels are not built here (they are specialised per model at ``put_model`` and
tested on CUDA upstream).
"""

from __future__ import annotations

import importlib
import re
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterable

from surgsim_envs.batch import backend
from surgsim_envs.batch.cubin_info import kernel_resources, occupancy
from surgsim_envs.errors import ConfigError

#: the backend's modules that hold Warp kernels (the ``@wp.func``-only modules compile inside them)
KERNEL_MODULES = (
    "surgsim_envs.batch.contact_kernels",
    "surgsim_envs.batch.mass_spring_kernels",
    "surgsim_envs.batch.rigid_kernels",
    "surgsim_envs.batch.reset_kernels",
    "surgsim_envs.batch.inclusion_kernels",
    "surgsim_envs.batch.palpation_kernels",
    "surgsim_envs.batch.grasp_kernels",
    "surgsim_envs.batch.slippage_kernels",
)
#: kernels launched in every physics substep of ``BatchSimulation.step`` (the hot loop), by module
SUBSTEP_KERNELS = {
    "surgsim_envs.batch.contact_kernels": ("gather_geoms", "advance_geoms", "contact_points", "tool_sums",
                                           "add_wrench", "write_reaction", "zero_reaction"),
    "surgsim_envs.batch.mass_spring_kernels": ("spring_forces", "volume_forces", "integrate_nodes"),
}
#: default architectures: 90 = H100 / H200 (Hopper), 80 = A100 (Ampere)
DEFAULT_ARCHS = (90,)
#: Warp's default threads per block of ``wp.launch``
BLOCK_DIM = 256

_SYMBOL = re.compile(r"^(?P<name>.+)_[0-9a-f]{8}_cuda_kernel_forward$")


class CudaBuildUnavailable(ConfigError):
    """Warp on this host cannot build CUDA binaries (no NVRTC in its build)."""


@dataclass(frozen=True)
class KernelReport:
    """One kernel of one module built for one architecture."""

    module: str
    kernel: str
    arch: int
    registers: int
    local_bytes: int
    occupancy: float
    substep: bool


def kernel_name(symbol: str) -> str | None:
    """The Warp kernel's name in a cubin symbol (``<name>_<hash>_cuda_kernel_forward``), else None."""
    m = _SYMBOL.match(symbol)
    return m.group("name") if m else None


def check_archs(archs: Iterable[int]) -> tuple[int, ...]:
    """Architectures as compute capabilities (major * 10 + minor, e.g. 80, 86, 89, 90); ConfigError else."""
    out = []
    for a in archs:
        if isinstance(a, bool) or not isinstance(a, int) or not 50 <= a <= 130:
            raise ConfigError(f"arch={a!r}: give a CUDA compute capability as major * 10 + minor, e.g. 80 (A100), "
                              "86 (RTX 30xx), 89 (RTX 40xx, L4), 90 (H100, H200)")
        out.append(int(a))
    if not out:
        raise ConfigError("give at least one CUDA architecture, e.g. 90")
    return tuple(dict.fromkeys(out))


def cuda_build_unavailable(arch: int = DEFAULT_ARCHS[0]) -> str | None:
    """None if Warp on this host can build CUDA binaries for ``arch`` (a one-line kernel is built to
    find out), else the reason. Only this check turns a failed build into "unavailable": a kernel of
    the backend that fails to build is an error (:func:`compile_module` raises it)."""
    try:
        wp, _ = backend.require()
    except backend.BatchUnavailableError as exc:
        return str(exc)

    @wp.kernel(module="unique")
    def probe(x: wp.array(dtype=wp.float64)):
        x[wp.tid()] = x[wp.tid()] * wp.float64(2.0)

    with tempfile.TemporaryDirectory(prefix="surgsim-cuda-probe-") as tmp:
        try:
            paths = wp.compile_aot_module(probe.module, arch=int(arch), module_dir=tmp, use_ptx=False)
        except Exception as exc:   # noqa: BLE001 - any failure here means "this Warp cannot build CUDA"
            return (f"Warp {wp.__version__} cannot build CUDA code for sm_{arch} on this host: "
                    f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__} (the warp-lang wheels for "
                    "Linux and Windows x86-64 include NVRTC)")
        if not any(str(p).endswith(".cubin") for p in paths):
            return f"Warp {wp.__version__} built no cubin for sm_{arch} (got {[str(p) for p in paths]})"
    return None


def compile_module(module_name: str, arch: int, out_dir: str | Path) -> tuple[Path, float]:
    """Build ``module_name``'s Warp kernels into a cubin for ``arch`` under ``out_dir``; (path, seconds).
    A compile error propagates (Warp's exception, naming the kernel)."""
    wp, _ = backend.require()
    module = importlib.import_module(module_name)
    t0 = time.perf_counter()
    paths = wp.compile_aot_module(module, arch=int(arch), module_dir=str(out_dir), use_ptx=False)
    seconds = time.perf_counter() - t0
    cubins = [Path(p) for p in paths if str(p).endswith(".cubin")]
    if not cubins:
        raise CudaBuildUnavailable(f"Warp built no cubin for {module_name} at sm_{arch} (got {[str(p) for p in paths]})")
    return cubins[0], seconds


def build(archs: Iterable[int] = DEFAULT_ARCHS, out_dir: str | Path | None = None, block_dim: int = BLOCK_DIM,
          modules: Iterable[str] = KERNEL_MODULES,
          progress: Callable[[str], None] | None = None) -> tuple[list[KernelReport], dict[str, float]]:
    """Build ``modules`` for every arch in ``archs`` (cubins under ``out_dir``, a temporary folder if
    None). Returns the kernel reports and the compile seconds per ``"module@sm_arch"``."""
    archs = check_archs(archs)
    reason = cuda_build_unavailable(archs[0])
    if reason is not None:
        raise CudaBuildUnavailable(reason)
    reports, seconds = [], {}
    with tempfile.TemporaryDirectory(prefix="surgsim-cuda-build-") as tmp:
        where = Path(out_dir) if out_dir is not None else Path(tmp)
        where.mkdir(parents=True, exist_ok=True)
        for arch in archs:
            for name in modules:
                if progress is not None:
                    progress(f"sm_{arch}: {name}")
                path, secs = compile_module(name, arch, where)
                seconds[f"{name}@sm_{arch}"] = secs
                hot = SUBSTEP_KERNELS.get(name, ())
                for k in kernel_resources(path):
                    kname = kernel_name(k.symbol)
                    if kname is None:
                        continue
                    reports.append(KernelReport(name, kname, arch, k.registers, k.local_bytes,
                                                occupancy(k.registers, block_dim, arch), kname in hot))
    return reports, seconds


def markdown(reports: list[KernelReport], seconds: dict[str, float], block_dim: int = BLOCK_DIM) -> str:
    """A table of the kernel reports (physics-substep kernels first), with the compile time per module."""
    lines = [f"| module | kernel | arch | per substep | registers / thread | local memory B / thread | "
             f"occupancy at {block_dim} threads / block |", "|---|---|---|---|---|---|---|"]
    for r in sorted(reports, key=lambda r: (r.arch, not r.substep, r.module, r.kernel)):
        lines.append(f"| {r.module.rsplit('.', 1)[-1]} | {r.kernel} | sm_{r.arch} | {'yes' if r.substep else ''} | "
                     f"{r.registers} | {r.local_bytes} | {r.occupancy * 100:g} % |")
    lines.append("")
    lines.append("Compile seconds (NVRTC, this host): " + ", ".join(
        f"{k.split('@')[0].rsplit('.', 1)[-1]} @{k.split('@')[1]} {v:.1f}" for k, v in seconds.items()))
    return "\n".join(lines)


def as_dicts(reports: list[KernelReport]) -> list[dict]:
    return [asdict(r) for r in reports]


__all__ = ["BLOCK_DIM", "CudaBuildUnavailable", "DEFAULT_ARCHS", "KERNEL_MODULES", "KernelReport", "SUBSTEP_KERNELS",
           "as_dicts", "build", "check_archs", "compile_module", "cuda_build_unavailable", "kernel_name", "markdown"]
