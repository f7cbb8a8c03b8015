"""What a compiled CUDA kernel costs an SM, read from its cubin: registers, local memory, occupancy.

A cubin (the GPU binary NVIDIA's compiler writes for one architecture) is an ELF64 file. Its global
``.nv.info`` section is a list of attribute records, each ``format (u8), attribute (u8), then
either a 16-bit value or a 16-bit length and that many payload bytes``. Per function it holds

* ``EIATTR_REGCOUNT`` (0x2f): (symbol index u32, registers per thread u32);
* ``EIATTR_FRAME_SIZE`` (0x11): (symbol index u32, bytes of per-thread local memory u32): spilled
  registers and local arrays the compiler could not keep in registers. 0 means none.

These are the figures ``ptxas -v`` prints; reading them from the binary needs no CUDA toolkit and no
GPU, so a CPU-only host can check what the batched backend's kernels will cost on a GPU
(:mod:`surgsim_envs.batch.cuda_build`).

:func:`occupancy` turns registers per thread into the share of an SM's warp slots a kernel can fill
(the CUDA occupancy calculator's register limit): registers are allocated per warp in units of 256,
an SM has 65,536 and holds at most 64 warps (sm_80, sm_90; 48 on sm_86 and sm_89) and 32 blocks.
Shared memory is not a limit here: the backend's kernels use none.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

#: attribute codes of the ``.nv.info`` records read here
EIATTR_FRAME_SIZE = 0x11
EIATTR_REGCOUNT = 0x2F
#: record format whose 16-bit field is the length of a payload that follows (the others carry a value)
EIFMT_SVAL = 0x04

#: per-SM limits used by :func:`occupancy`: registers, register allocation unit per warp, warps, blocks
REGISTERS_PER_SM = 65536
REGISTER_UNIT = 256
MAX_BLOCKS_PER_SM = 32
#: resident warps per SM by compute capability (major * 10 + minor); others: 64
MAX_WARPS_PER_SM = {86: 48, 87: 48, 89: 48, 120: 48}


class CubinError(ValueError):
    """The file is not a cubin this reader understands (named, with what was wrong)."""


@dataclass(frozen=True)
class KernelResources:
    """One kernel of a cubin: its symbol, registers per thread and local-memory bytes per thread."""

    symbol: str
    registers: int
    local_bytes: int


def _sections(blob: bytes) -> list[dict]:
    if blob[:4] != b"\x7fELF" or blob[4] != 2:
        raise CubinError("not a 64-bit ELF file (a cubin starts with 0x7f 'ELF', class 2)")
    shoff, = struct.unpack_from("<Q", blob, 0x28)
    shentsize, shnum, shstrndx = struct.unpack_from("<HHH", blob, 0x3A)
    out = []
    for i in range(shnum):
        name, _typ, _flags, _addr, off, size, link, _info, _align, _ent = struct.unpack_from(
            "<IIQQQQIIQQ", blob, shoff + i * shentsize)
        out.append({"name_at": name, "off": off, "size": size, "link": link})
    names = out[shstrndx]
    for s in out:
        start = names["off"] + s["name_at"]
        s["name"] = blob[start:blob.index(b"\0", start)].decode("ascii", "replace")
    return out


def _symbols(blob: bytes, sections: list[dict]) -> list[str]:
    table = next((s for s in sections if s["name"] == ".symtab"), None)
    if table is None:
        raise CubinError("no .symtab section")
    strings = sections[table["link"]]
    names = []
    for i in range(table["size"] // 24):
        at, = struct.unpack_from("<I", blob, table["off"] + 24 * i)
        start = strings["off"] + at
        names.append(blob[start:blob.index(b"\0", start)].decode("ascii", "replace"))
    return names


def _records(blob: bytes, section: dict):
    """(attribute, payload bytes or 16-bit value) of every record of an ``.nv.info`` section."""
    at, end = section["off"], section["off"] + section["size"]
    while at + 4 <= end:
        fmt, attr, field = blob[at], blob[at + 1], struct.unpack_from("<H", blob, at + 2)[0]
        if fmt == EIFMT_SVAL:
            if at + 4 + field > end:
                raise CubinError(f"an .nv.info record at byte {at} runs past its section")
            yield attr, blob[at + 4:at + 4 + field]
            at += 4 + field
        else:
            yield attr, field
            at += 4


def kernel_resources(path: str | Path) -> list[KernelResources]:
    """Registers and local-memory bytes per thread of every kernel (entry function) in the cubin
    ``path``, in symbol order. Device functions the compiler kept separate are not listed (their
    registers count in their callers')."""
    blob = Path(path).read_bytes()
    try:
        sections = _sections(blob)
        symbols = _symbols(blob, sections)
        info = next((s for s in sections if s["name"] == ".nv.info"), None)
        if info is None:
            raise CubinError("no .nv.info section")
        regs, frame = {}, {}
        for attr, payload in _records(blob, info):
            if attr in (EIATTR_REGCOUNT, EIATTR_FRAME_SIZE) and isinstance(payload, bytes) and len(payload) >= 8:
                sym, value = struct.unpack_from("<II", payload)
                (regs if attr == EIATTR_REGCOUNT else frame)[sym] = value
    except (struct.error, IndexError, ValueError) as exc:
        if isinstance(exc, CubinError):
            raise CubinError(f"{path}: {exc}") from None
        raise CubinError(f"{path}: truncated or malformed ELF ({exc})") from None
    # an entry function (a kernel) has its own ".nv.info.<name>" section; device functions do not
    entry = {sec["name"][len(".nv.info."):] for sec in sections if sec["name"].startswith(".nv.info.")}
    kernels = [s for s in sorted(regs) if symbols[s] in entry]
    return [KernelResources(symbols[s], int(regs[s]), int(frame.get(s, 0))) for s in kernels]


def occupancy(registers: int, block_dim: int = 256, arch: int = 90) -> float:
    """Share (0-1) of an SM's warp slots that blocks of ``block_dim`` threads using ``registers``
    per thread can fill, on compute capability ``arch`` (e.g. 90 for H100/H200, 80 for A100),
    counting the register limit only (module docstring). 0: one block needs more registers than an
    SM has, and the launch would fail."""
    if not 1 <= int(registers) <= 255:
        raise ValueError(f"registers={registers}: a CUDA thread uses 1 to 255 registers")
    if not 1 <= int(block_dim) <= 1024:
        raise ValueError(f"block_dim={block_dim}: a CUDA block holds 1 to 1024 threads")
    max_warps = MAX_WARPS_PER_SM.get(int(arch), 64)
    warps_per_block = math.ceil(int(block_dim) / 32)
    per_warp = math.ceil(int(registers) * 32 / REGISTER_UNIT) * REGISTER_UNIT
    blocks = min(REGISTERS_PER_SM // (per_warp * warps_per_block), MAX_BLOCKS_PER_SM, max_warps // warps_per_block)
    return blocks * warps_per_block / max_warps


__all__ = ["CubinError", "KernelResources", "kernel_resources", "occupancy"]
