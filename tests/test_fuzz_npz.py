"""Hostile ``.npz`` policy files: damaged archives, decompression bombs and arrays of the wrong
kind are refused by what the file declares, before anything is allocated or run."""

from __future__ import annotations

import io
import zipfile

import numpy as np
import pytest

pytest.importorskip("hypothesis", reason="hypothesis is in the [test] extra")
from hypothesis import HealthCheck, given, settings  # noqa: E402

import fuzz_surfaces as fs  # noqa: E402
from fuzz_harness import check  # noqa: E402
from surgsim_envs.errors import ConfigError  # noqa: E402
from surgsim_envs.policies.npz_policy import MAX_FILE_BYTES, NpzPolicy  # noqa: E402

FAST = settings(max_examples=80, deadline=None, database=None, suppress_health_check=list(HealthCheck))
MORE = settings(max_examples=1500, deadline=None, database=None, suppress_health_check=list(HealthCheck))


@FAST
@given(fs.npz_case())
def test_fuzz_npz_policy_files(case):
    check(fs.run_npz, case, timeout_s=20)


@pytest.mark.slow
@MORE
@given(fs.npz_case())
def test_fuzz_npz_policy_files_more(case):
    check(fs.run_npz, case, timeout_s=20)


@pytest.fixture
def good(tmp_path):
    path = tmp_path / "good.npz"
    path.write_bytes(fs.good_policy_bytes())
    return path


def test_truncated_archive(good):
    raw = good.read_bytes()
    good.write_bytes(raw[: len(raw) // 2])
    with pytest.raises(ConfigError, match="not a readable .npz archive .*BadZipFile"):
        NpzPolicy.load(good)


def test_bad_crc(good):
    raw = bytearray(good.read_bytes())
    raw[raw.index(b"\x93NUMPY") + 130] ^= 0xFF          # a data byte of the first (stored) member
    good.write_bytes(bytes(raw))
    with pytest.raises(ConfigError, match="Bad CRC-32"):
        NpzPolicy.load(good)


def test_a_member_declaring_4_gib_is_refused_before_decompressing(good):
    raw = bytearray(good.read_bytes())
    central = raw.index(b"PK\x01\x02")                 # the first member's central directory entry
    raw[central + 24:central + 28] = (0xFFFFFFFE).to_bytes(4, "little")   # uncompressed size: 4 GiB
    good.write_bytes(bytes(raw))
    with pytest.raises(ConfigError, match=f"declare 4,294,96.* bytes uncompressed, more than the {MAX_FILE_BYTES:,}"):
        NpzPolicy.load(good)


def test_a_header_declaring_more_than_the_member_holds_is_refused(tmp_path):
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f8", "fortran_order": False, "shape": (1 << 29, 1)})
    with zipfile.ZipFile(tmp_path / "h.npz", "w") as zf:
        zf.writestr("W0.npy", header.getvalue() + bytes(16))
    with pytest.raises(ConfigError, match=r"member 'W0' declares shape \(536870912, 1\) of float64"):
        NpzPolicy.load(tmp_path / "h.npz")


def test_a_member_flagged_encrypted_is_refused(good):
    raw = bytearray(good.read_bytes())
    central = raw.index(b"PK\x01\x02")
    raw[central + 8] |= 1                                # general-purpose flag bit 0: "encrypted"
    good.write_bytes(bytes(raw))
    with pytest.raises(ConfigError, match="is encrypted"):
        NpzPolicy.load(good)


@pytest.mark.parametrize("value, message", [
    (np.full((3, 4), 1j), "member 'W0' has dtype complex128"),
    (np.full((3, 4), "a"), "member 'W0' has dtype <U1"),
    (np.full((3, 4), np.datetime64("2020-01-01")), "member 'W0' has dtype datetime64"),
    (np.full((3, 4), True), "member 'W0' has dtype bool"),
    (np.full((3, 4), 1e300), r"W0 holds 1e\+300, above the limit of 1e\+12"),
])
def test_weights_of_the_wrong_kind_or_size_are_refused(tmp_path, good, value, message):
    with np.load(good) as z:
        arrays = {k: z[k] for k in z.files}
    arrays["W0"] = value
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ConfigError, match=message):
        NpzPolicy.load(tmp_path / "bad.npz")


def test_constructor_refuses_complex_and_string_arrays():
    with pytest.raises(ConfigError, match="W0 has dtype complex128"):
        NpzPolicy([np.ones((2, 2)) * 1j], [np.zeros(2)])
    with pytest.raises(ConfigError, match="b0 has dtype <U3"):
        NpzPolicy([np.ones((2, 2))], [np.array(["1.0", "2.0"])])
