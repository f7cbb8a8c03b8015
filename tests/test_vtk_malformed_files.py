"""Legacy VTK reader on malformed files: errors name the file and the line, and no
declared count can make the reader loop or burn time beyond the file size."""

from __future__ import annotations

import os

import numpy as np
import pytest

from surgsim_envs.errors import ConfigError
from surgsim_envs.geometry.loaders import load_tet_mesh
from surgsim_envs.geometry.vtk_legacy import read_legacy_vtk

HEAD = "# vtk DataFile Version 2.0\nt\n{fmt}\nDATASET UNSTRUCTURED_GRID\n"
TET_PTS = "0 0 0\n1 0 0\n0 1 0\n0 0 1\n"


def _ascii(tmp_path, body: str):
    f = tmp_path / "m.vtk"
    f.write_text(HEAD.format(fmt="ASCII") + body)
    return f


def test_a_valid_ascii_tet_reads(tmp_path):
    f = _ascii(tmp_path, "POINTS 4 float\n" + TET_PTS + "CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10\n")
    pts, (conn, off), types = read_legacy_vtk(f)
    assert pts.shape == (4, 3) and conn.tolist() == [0, 1, 2, 3] and off.tolist() == [0, 4] and types.tolist() == [10]


def test_mixed_cell_sizes_keep_their_connectivity(tmp_path):
    f = _ascii(tmp_path, "POINTS 4 float\n" + TET_PTS + "CELLS 3 12\n3 0 1 2\n4 0 1 2 3\n2 2 3\nCELL_TYPES 3\n5\n10\n3\n")
    pts, (conn, off), types = read_legacy_vtk(f)
    assert conn.tolist() == [0, 1, 2, 0, 1, 2, 3, 2, 3] and off.tolist() == [0, 3, 7, 9]
    assert len(load_tet_mesh(f).tets) == 1


def test_negative_points_count_in_a_binary_file_fails_at_once(tmp_path):
    f = tmp_path / "neg.vtk"
    f.write_bytes(HEAD.format(fmt="BINARY").encode() + b"POINTS -5 double\n" + b"\x00" * 64)
    with pytest.raises(ConfigError, match=r"neg\.vtk, line 5: .*point count -5 is negative"):
        read_legacy_vtk(f)


@pytest.mark.parametrize("fmt", ["ASCII", "BINARY"])
def test_huge_declared_counts_fail_before_any_work(tmp_path, fmt):
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.0]])
    body = b"POINTS 4 double\n" + (pts.astype(">f8").tobytes() + b"\n" if fmt == "BINARY" else TET_PTS.encode())
    f = tmp_path / "huge.vtk"
    f.write_bytes(HEAD.format(fmt=fmt).encode() + body + b"CELLS 1000000000000 5000000000000\n4 0 1 2 3\n")
    with pytest.raises(ConfigError, match=r"huge\.vtk, line \d+: .*declares 5000000000000 values but only \d+ bytes"):
        read_legacy_vtk(f)
    f.write_bytes(HEAD.format(fmt=fmt).encode() + b"POINTS 999999999999 float\n0 0 0\n")
    with pytest.raises(ConfigError, match=r"line 5: .*declares 2999999999997 values"):
        read_legacy_vtk(f)


@pytest.mark.parametrize("body, line, message", [
    ("POINTS\n", 5, "lacks its point count"),
    ("POINTS four float\n", 5, "point count 'four' is not an integer"),
    ("POINTS 4\n" + TET_PTS, 5, "lacks its data type"),
    ("POINTS 4 quaternion\n" + TET_PTS, 5, "unknown data type 'quaternion'"),
    ("POINTS 4 float\n0 0 0\n1 0 x\n0 1 0\n0 0 1\n", 9, "value 'x' is not a valid float64"),
    ("POINTS 4 float\n0 0 0\nnan 0 0\n0 1 0\n0 0 1\n", 5, r"point #1 is not finite"),
    ("POINTS 4 float\n" + TET_PTS + "CELLS 1 5\n4 0 1 2 7\nCELL_TYPES 1\n10\n", 10, "refers to point 7, outside"),
    ("POINTS 4 float\n" + TET_PTS + "CELLS 1 5\n4 0 1 -2 3\nCELL_TYPES 1\n10\n", 10, "refers to point -2"),
    ("POINTS 4 float\n" + TET_PTS + "CELLS 2 5\n9 0 1 2 3\nCELL_TYPES 2\n10 10\n", 10, "cell #0 declares 9 points"),
    ("POINTS 4 float\n" + TET_PTS + "CELLS 3 2\n4 0\n", 10, "3 cells in 2 integers"),
    ("POINTS 4 float\n" + TET_PTS + "CELLS 2 4\nOFFSETS vtktypeint64\n0 9\nCONNECTIVITY vtktypeint64\n0 1 2 3\n"
     "CELL_TYPES 1\n10\n", 10, "OFFSETS must start at 0"),
    ("POINTS 4 float\n" + TET_PTS + "CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 2\n10\n", 13, "file ends after 1 of 2"),
    ("POINTS 4 float\n" + TET_PTS + "CELLS 1 5\n4 0 1 2 3\nCELL_TYPES 1\n10 10\n", 13, "expected 1 values, found 2"),
    ("POINTS 4 float\n" + TET_PTS, 9, r"missing section\(s\) \['CELLS', 'CELL_TYPES'\]"),
    ("POINTS 4 float\n" + TET_PTS + "CELLS 1 5\n4 0 1 2 99999999999999999999999\nCELL_TYPES 1\n10\n", 11,
     "not a valid int64"),
])
def test_malformed_files_name_the_file_and_line(tmp_path, body, line, message):
    f = _ascii(tmp_path, body)
    with pytest.raises(ConfigError, match=rf"m\.vtk, line {line}: .*{message}"):
        read_legacy_vtk(f)


def test_a_fifo_is_refused_instead_of_blocking(tmp_path):
    fifo = tmp_path / "pipe.vtk"
    os.mkfifo(fifo)
    with pytest.raises(ConfigError, match="not a regular file"):
        read_legacy_vtk(fifo)
