"""``surgsim bench cuda-build``: build the batched backend's Warp kernels for CUDA GPUs on this host
(NVRTC, no GPU needed) and report registers, local memory and occupancy per kernel
(:mod:`surgsim_envs.batch.cuda_build`). Writes ``cuda_build.json`` and ``cuda_build.md`` under
``--out``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from surgsim_envs.errors import ConfigError


def parse_archs(text: str) -> list[int]:
    """Architectures from "80,90" (ConfigError naming the bad entry)."""
    out = []
    for part in str(text).split(","):
        part = part.strip().lower().removeprefix("sm_")
        if not part.isdigit():
            raise ConfigError(f"--arch entry {part!r} is not a compute capability; give e.g. 90 or 80,90")
        out.append(int(part))
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--arch", default="90",
                        help="comma-separated CUDA compute capabilities (major*10+minor): 90 = H100/H200 (default), "
                             "80 = A100, 89 = L4/RTX 40xx, 86 = RTX 30xx")
    parser.add_argument("--block-dim", type=int, default=256, help="threads per block for the occupancy (Warp's default 256)")
    parser.add_argument("--json", action="store_true", help="print the kernel reports as JSON instead of the table")
    parser.add_argument("--out", default="surgsim-out/cuda_build", help="output directory (cubins, JSON, markdown)")


def run(args) -> int:
    from surgsim_envs.batch import cuda_build as cb

    archs = cb.check_archs(parse_archs(args.arch))
    if not 1 <= int(args.block_dim) <= 1024:
        raise ConfigError(f"--block-dim {args.block_dim}: a CUDA block holds 1 to 1024 threads")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    reports, seconds = cb.build(archs, out_dir=out / "cubin", block_dim=int(args.block_dim),
                                progress=lambda text: print(f"building {text}", file=sys.stderr, flush=True))
    table = cb.markdown(reports, seconds, int(args.block_dim))
    data = {"archs": list(archs), "block_dim": int(args.block_dim), "kernels": cb.as_dicts(reports),
            "compile_seconds": seconds}
    (out / "cuda_build.json").write_text(json.dumps(data, indent=1))
    (out / "cuda_build.md").write_text(table + "\n")
    print(json.dumps(data, indent=1) if args.json else table)
    spills = [r for r in reports if r.substep and r.local_bytes > 0]
    for r in spills:
        print(f"warning: {r.kernel} (per substep) uses {r.local_bytes} B of local memory per thread at sm_{r.arch}",
              file=sys.stderr)
    print(f"wrote {out / 'cuda_build.json'} and {out / 'cuda_build.md'}", file=sys.stderr)
    return 0
