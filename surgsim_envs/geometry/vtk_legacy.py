"""Minimal reader for legacy VTK UNSTRUCTURED_GRID files (ASCII and BINARY), numpy only.

Reads POINTS, CELLS (both the classic ``CELLS n size`` list and the VTK >= 5.1 ``OFFSETS`` /
``CONNECTIVITY`` layout) and CELL_TYPES; everything after them (POINT_DATA, CELL_DATA, FIELD) is
ignored. Binary legacy VTK is big-endian.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError

VTK_TETRA = 10

_DTYPES = {
    "float": ">f4", "double": ">f8", "int": ">i4", "unsigned_int": ">u4", "long": ">i8",
    "unsigned_long": ">u8", "short": ">i2", "unsigned_short": ">u2", "char": ">i1", "unsigned_char": ">u1",
    "vtktypeint64": ">i8", "vtktypeint32": ">i4", "vtktypeuint64": ">u8", "vtktypeuint32": ">u4",
    "vtkidtype": ">i8",
}


class _Reader:
    def __init__(self, data: bytes, binary: bool, path: Path):
        self.data, self.pos, self.binary, self.path = data, 0, binary, path

    def error(self, msg: str) -> ConfigError:
        return ConfigError(f"{self.path}: not a readable legacy VTK tet mesh ({msg}); "
                           "re-export it as legacy VTK UNSTRUCTURED_GRID (e.g. meshio.write(..., file_format='vtk'))")

    def line(self) -> str | None:
        """Next non-empty text line (stripped), or None at the end."""
        while self.pos < len(self.data):
            end = self.data.find(b"\n", self.pos)
            end = len(self.data) if end < 0 else end
            text = self.data[self.pos:end].decode("latin-1").strip()
            self.pos = end + 1
            if text:
                return text
        return None

    def array(self, count: int, dtype: str) -> np.ndarray:
        if dtype.lower() not in _DTYPES:
            raise self.error(f"unknown data type {dtype!r}")
        dt = np.dtype(_DTYPES[dtype.lower()])
        if self.binary:
            nbytes = count * dt.itemsize
            if self.pos + nbytes > len(self.data):
                raise self.error("file ends inside a binary array")
            out = np.frombuffer(self.data, dtype=dt, count=count, offset=self.pos)
            self.pos += nbytes
            return out.astype(np.float64 if dt.kind == "f" else np.int64)
        values: list[str] = []
        while len(values) < count:
            text = self.line()
            if text is None:
                raise self.error(f"file ends after {len(values)} of {count} values")
            values.extend(text.split())
        if len(values) != count:
            raise self.error(f"expected {count} values, found {len(values)} before the next section")
        kind = np.float64 if dt.kind == "f" else np.int64
        try:
            return np.array(values, dtype=kind)
        except ValueError:
            raise self.error(f"non-numeric value in a {dtype} array") from None


def read_legacy_vtk(path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (P, 3) float64 (file units), cell connectivity as a flat int64 array and offsets (C+1,),
    and cell types (C,). Returns ``(points, (connectivity, offsets), types)``."""
    path = Path(path)
    data = path.read_bytes()
    head = _Reader(data, False, path)
    first = head.line()
    if first is None or not first.lower().startswith("# vtk datafile"):
        raise head.error("missing '# vtk DataFile Version' header")
    head.line()  # title
    fmt = (head.line() or "").upper()
    if fmt not in ("ASCII", "BINARY"):
        raise head.error(f"format line must be ASCII or BINARY, got {fmt!r}")
    rd = _Reader(data, fmt == "BINARY", path)
    rd.pos = head.pos
    dataset = (rd.line() or "").upper().split()
    if dataset != ["DATASET", "UNSTRUCTURED_GRID"]:
        raise rd.error(f"dataset must be UNSTRUCTURED_GRID, got {' '.join(dataset)!r}")
    points = conn = offsets = types = None
    while True:
        text = rd.line()
        if text is None:
            break
        tok = text.split()
        key = tok[0].upper()
        if key == "POINTS":
            n = int(tok[1])
            points = rd.array(3 * n, tok[2]).reshape(n, 3).astype(np.float64)
        elif key == "CELLS":
            a, b = int(tok[1]), int(tok[2])
            nxt = rd.pos
            peek = rd.line() if rd.binary is False else None
            if rd.binary:
                # VTK >= 5.1 writes "OFFSETS <type>" right after CELLS; the classic layout has raw data.
                probe = data[rd.pos:rd.pos + 16]
                is_new = probe.lstrip().upper().startswith(b"OFFSETS")
            else:
                is_new = peek is not None and peek.upper().startswith("OFFSETS")
            rd.pos = nxt
            if is_new:
                off_tok = (rd.line() or "").split()
                offsets = rd.array(a, off_tok[1]).astype(np.int64)
                con_tok = (rd.line() or "").split()
                if not con_tok or con_tok[0].upper() != "CONNECTIVITY":
                    raise rd.error("OFFSETS not followed by CONNECTIVITY")
                conn = rd.array(b, con_tok[1]).astype(np.int64)
            else:
                raw = rd.array(b, "int").astype(np.int64)
                offsets = np.zeros(a + 1, dtype=np.int64)
                conn_parts = []
                p = 0
                sizes = np.empty(a, dtype=np.int64)
                for c in range(a):  # cell count is small compared with reading cost
                    if p >= len(raw):
                        raise rd.error("CELLS list shorter than declared")
                    k = int(raw[p])
                    sizes[c] = k
                    conn_parts.append(raw[p + 1:p + 1 + k])
                    p += k + 1
                offsets[1:] = np.cumsum(sizes)
                conn = np.concatenate(conn_parts) if conn_parts else np.zeros(0, np.int64)
        elif key == "CELL_TYPES":
            types = rd.array(int(tok[1]), "int").astype(np.int64)
            break
        elif key in ("POINT_DATA", "CELL_DATA"):
            break
        elif key == "METADATA":
            continue
        else:
            continue
    if points is None or conn is None or types is None:
        missing = [n for n, v in (("POINTS", points), ("CELLS", conn), ("CELL_TYPES", types)) if v is None]
        raise rd.error(f"missing section(s) {missing}")
    if len(types) != len(offsets) - 1:
        raise rd.error(f"{len(offsets) - 1} cells but {len(types)} cell types")
    return points, (conn, offsets), types


def tets_from_cells(conn: np.ndarray, offsets: np.ndarray, types: np.ndarray) -> np.ndarray:
    """(T, 4) int64 node indices of the tetrahedral cells (VTK type 10)."""
    sel = np.flatnonzero((types == VTK_TETRA) & (np.diff(offsets) == 4))
    idx = offsets[sel][:, None] + np.arange(4)[None, :]
    return conn[idx].astype(np.int64)
