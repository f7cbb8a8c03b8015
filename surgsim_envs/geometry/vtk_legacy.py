"""Minimal reader for legacy VTK UNSTRUCTURED_GRID files (ASCII and BINARY), numpy only.

Reads POINTS, CELLS (both the classic ``CELLS n size`` list and the VTK >= 5.1 ``OFFSETS`` /
``CONNECTIVITY`` layout) and CELL_TYPES; everything after them (POINT_DATA, CELL_DATA, FIELD) is
ignored. Binary legacy VTK is big-endian.

Untrusted files: every malformed file raises :class:`~surgsim_envs.errors.ConfigError` naming the
file and the line (the line of the section header for errors inside a binary array). Every
declared count is checked against the bytes left in the file *before* anything is allocated or
looped over (a value takes at least 2 bytes in ASCII, its item size in BINARY), so the work is
bounded by the file size: a negative or huge count fails at once instead of looping or burning
time. Only regular files are read (a FIFO or a device would block or never end). Point
coordinates must be finite; connectivity indices must lie in ``[0, number of points)``; offsets
must start at 0, never decrease and end at the connectivity length.
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
    """Cursor over the file bytes that knows its line number (1-based)."""

    def __init__(self, data: bytes, binary: bool, path: Path):
        self.data, self.pos, self.binary, self.path = data, 0, binary, path
        self.lineno = 0  # line of the last line returned by line()
        self._next_line = 1  # line the cursor is on

    def error(self, msg: str, lineno: int | None = None) -> ConfigError:
        where = lineno if lineno is not None else max(self.lineno, 1)
        return ConfigError(f"{self.path}, line {where}: not a readable legacy VTK tet mesh ({msg}); "
                           "re-export it as legacy VTK UNSTRUCTURED_GRID (e.g. meshio.write(..., file_format='vtk'))")

    def line(self) -> str | None:
        """Next non-empty text line (stripped), or None at the end."""
        while self.pos < len(self.data):
            end = self.data.find(b"\n", self.pos)
            end = len(self.data) if end < 0 else end
            text = self.data[self.pos:end].decode("latin-1").strip()
            self.pos = end + 1
            self.lineno = self._next_line
            self._next_line += 1
            if text:
                return text
        return None

    def remaining(self) -> int:
        return max(len(self.data) - self.pos, 0)

    def count(self, tok: list[str], i: int, what: str) -> int:
        """Token ``i`` of a section header as a non-negative count the rest of the file can hold."""
        if len(tok) <= i:
            raise self.error(f"'{' '.join(tok)}' lacks its {what}")
        try:
            n = int(tok[i])
        except ValueError:
            raise self.error(f"{what} {tok[i]!r} is not an integer") from None
        if n < 0:
            raise self.error(f"{what} {n} is negative")
        return n

    def dtype(self, tok: list[str], i: int) -> np.dtype:
        if len(tok) <= i:
            raise self.error(f"'{' '.join(tok)}' lacks its data type")
        name = tok[i].lower()
        if name not in _DTYPES:
            raise self.error(f"unknown data type {tok[i]!r}; expected one of {sorted(_DTYPES)}")
        return np.dtype(_DTYPES[name])

    def array(self, count: int, dt: np.dtype, what: str) -> np.ndarray:
        """``count`` values of type ``dt`` (float64 or int64), bounded by the bytes left."""
        header = self.lineno
        need = count * dt.itemsize if self.binary else 2 * count - 1
        if count and need > self.remaining():
            raise self.error(f"{what} declares {count} values but only {self.remaining()} bytes follow "
                             f"(at least {need} needed)", header)
        kind = np.float64 if dt.kind == "f" else np.int64
        if count == 0:
            return np.zeros(0, dtype=kind)
        if self.binary:
            out = np.frombuffer(self.data, dtype=dt, count=count, offset=self.pos)
            self._next_line += self.data.count(b"\n", self.pos, self.pos + need)
            self.pos += need
            return out.astype(kind)
        values: list[str] = []
        while len(values) < count:
            text = self.line()
            if text is None:
                raise self.error(f"{what}: file ends after {len(values)} of {count} values")
            values.extend(text.split())
        if len(values) != count:
            raise self.error(f"{what}: expected {count} values, found {len(values)} before the next section")
        try:
            return np.array(values, dtype=kind)
        except (ValueError, OverflowError):
            bad = next((v for v in values if not _parses(v, kind)), "?")
            raise self.error(f"{what}: value {bad!r} is not a valid {kind.__name__} number") from None


def _parses(value: str, kind) -> bool:
    try:
        np.array([value], dtype=kind)
    except (ValueError, OverflowError):
        return False
    return True


def _cells_classic(rd: _Reader, a: int, b: int, header: int) -> tuple[np.ndarray, np.ndarray]:
    """The ``CELLS a b`` list: ``a`` records ``k i_1 .. i_k`` in ``b`` integers."""
    if a > b:
        raise rd.error(f"CELLS declares {a} cells in {b} integers (each cell needs at least its size)", header)
    raw = rd.array(b, np.dtype(">i4"), "CELLS")
    if a == 0:
        return np.zeros(0, np.int64), np.zeros(1, np.int64)
    k0 = int(raw[0])
    if k0 >= 0 and a * (k0 + 1) == b and np.all(raw[:: k0 + 1] == k0):  # uniform cells: vectorised
        conn = raw.reshape(a, k0 + 1)[:, 1:].reshape(-1)
        return conn, np.arange(a + 1, dtype=np.int64) * k0
    sizes = np.empty(a, dtype=np.int64)
    starts = np.empty(a, dtype=np.int64)
    p = 0
    for c in range(a):  # bounded: a <= b <= bytes in the file
        if p >= b:
            raise rd.error(f"CELLS list ends after {c} of {a} declared cells", header)
        k = int(raw[p])
        if k < 0 or p + 1 + k > b:
            raise rd.error(f"cell #{c} declares {k} points, which does not fit the CELLS list", header)
        sizes[c], starts[c] = k, p + 1
        p += k + 1
    if p != b:
        raise rd.error(f"CELLS list holds {b} integers but its {a} cells use {p}", header)
    offsets = np.zeros(a + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(sizes)
    idx = np.repeat(starts - offsets[:-1], sizes) + np.arange(offsets[-1])
    return raw[idx], offsets


def read_legacy_vtk(path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points (P, 3) float64 (file units), cell connectivity as a flat int64 array and offsets (C+1,),
    and cell types (C,). Returns ``(points, (connectivity, offsets), types)``; raises
    :class:`ConfigError` naming the file and line for anything malformed (see module docstring)."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{path}: not a regular file (missing, a directory, a FIFO or a device); "
                          "give the path of a legacy VTK file")
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc})") from None
    head = _Reader(data, False, path)
    first = head.line()
    if first is None or not first.lower().startswith("# vtk datafile"):
        raise head.error("missing '# vtk DataFile Version' header")
    head.line()  # title
    fmt = (head.line() or "").upper()
    if fmt not in ("ASCII", "BINARY"):
        raise head.error(f"format line must be ASCII or BINARY, got {fmt!r}")
    rd = _Reader(data, fmt == "BINARY", path)
    rd.pos, rd.lineno, rd._next_line = head.pos, head.lineno, head._next_line
    dataset = (rd.line() or "").upper().split()
    if dataset != ["DATASET", "UNSTRUCTURED_GRID"]:
        raise rd.error(f"dataset must be UNSTRUCTURED_GRID, got {' '.join(dataset)!r}")
    points = conn = offsets = types = None
    cells_line = None
    while True:
        text = rd.line()
        if text is None:
            break
        tok = text.split()
        key = tok[0].upper()
        header = rd.lineno
        if key == "POINTS":
            n = rd.count(tok, 1, "point count")
            points = rd.array(3 * n, rd.dtype(tok, 2), "POINTS").reshape(n, 3)
            if not np.all(np.isfinite(points)):
                bad = int(np.flatnonzero(~np.all(np.isfinite(points), axis=1))[0])
                raise rd.error(f"point #{bad} is not finite: {points[bad].tolist()}", header)
        elif key == "CELLS":
            cells_line = header
            a, b = rd.count(tok, 1, "cell count"), rd.count(tok, 2, "CELLS list size")
            if rd.binary:  # VTK >= 5.1 writes "OFFSETS <type>" right after CELLS
                is_new = data[rd.pos:rd.pos + 16].lstrip().upper().startswith(b"OFFSETS")
            else:
                save = (rd.pos, rd.lineno, rd._next_line)
                peek = rd.line()
                rd.pos, rd.lineno, rd._next_line = save
                is_new = peek is not None and peek.upper().startswith("OFFSETS")
            if is_new:
                off_tok = (rd.line() or "").split()
                offsets = rd.array(a, rd.dtype(off_tok, 1), "OFFSETS")
                con_tok = (rd.line() or "").split()
                if not con_tok or con_tok[0].upper() != "CONNECTIVITY":
                    raise rd.error("OFFSETS not followed by CONNECTIVITY")
                conn = rd.array(b, rd.dtype(con_tok, 1), "CONNECTIVITY")
                if len(offsets) == 0:
                    offsets = np.zeros(1, np.int64)
                if offsets[0] != 0 or offsets[-1] != len(conn) or np.any(np.diff(offsets) < 0):
                    raise rd.error(f"OFFSETS must start at 0, never decrease and end at {len(conn)} "
                                   f"(the CONNECTIVITY length); got {offsets[0]} .. {offsets[-1]}", header)
            else:
                conn, offsets = _cells_classic(rd, a, b, header)
        elif key == "CELL_TYPES":
            types = rd.array(rd.count(tok, 1, "cell type count"), np.dtype(">i4"), "CELL_TYPES")
            break
        elif key in ("POINT_DATA", "CELL_DATA"):
            break
    if points is None or conn is None or types is None:
        missing = [n for n, v in (("POINTS", points), ("CELLS", conn), ("CELL_TYPES", types)) if v is None]
        raise rd.error(f"missing section(s) {missing}")
    if len(types) != len(offsets) - 1:
        raise rd.error(f"{len(offsets) - 1} cells but {len(types)} cell types")
    if len(conn) and (conn.min() < 0 or conn.max() >= len(points)):
        bad = int(conn[(conn < 0) | (conn >= len(points))][0])
        raise rd.error(f"a cell refers to point {bad}, outside [0, {len(points)})", cells_line)
    return points, (conn, offsets), types


def tets_from_cells(conn: np.ndarray, offsets: np.ndarray, types: np.ndarray) -> np.ndarray:
    """(T, 4) int64 node indices of the tetrahedral cells (VTK type 10)."""
    sel = np.flatnonzero((types == VTK_TETRA) & (np.diff(offsets) == 4))
    idx = offsets[sel][:, None] + np.arange(4)[None, :]
    return conn[idx].astype(np.int64)
