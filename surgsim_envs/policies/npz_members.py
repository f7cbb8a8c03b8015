"""What a ``.npz`` file declares, read before any array is allocated.

A ``.npz`` file is a zip archive of ``.npy`` members. :func:`declared_arrays` reads the zip
directory and each member's ``.npy`` header only (a few hundred bytes each), so a truncated
archive, a member whose declared size is 4 GiB (a decompression bomb), or an array of an
unexpected dtype (complex, datetime, object, bytes) is refused before numpy allocates or
decompresses anything. Bad CRCs surface when the data is read; :func:`read_arrays` turns them
(and every other archive error) into ConfigError.
"""

from __future__ import annotations

import zipfile
import zlib
from pathlib import Path

import numpy as np

from surgsim_envs.errors import ConfigError

#: dtype kinds of numeric arrays (float, signed and unsigned int) and of text arrays (unicode)
NUMERIC_KINDS = "fiu"
#: what zipfile / zlib / numpy raise on a damaged archive (RuntimeError: a member flagged as
#: encrypted; NotImplementedError: an unknown compression method)
ARCHIVE_ERRORS = (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError, KeyError, RuntimeError,
                  NotImplementedError)
TEXT_KINDS = "U"


def declared_arrays(path, *, max_members: int, max_bytes: int, text_keys=()) -> dict[str, tuple]:
    """``{name: (shape, dtype)}`` of every member of the ``.npz`` file ``path``, from the zip
    directory and the ``.npy`` headers. ConfigError if the file is not a zip of ``.npy`` members,
    has more than ``max_members`` members, declares more than ``max_bytes`` bytes (compressed
    sizes do not count: a bomb is small on disk), or holds an array whose dtype is not numeric
    (``text_keys``: the members that must be text instead)."""
    p = Path(path)
    where = f"npz file {str(p)!r}"
    try:
        with zipfile.ZipFile(p) as zf:
            infos = zf.infolist()
            if len(infos) > max_members:
                raise ConfigError(f"{where}: {len(infos)} members, more than the {max_members} this format has")
            declared = sum(i.file_size for i in infos)
            if declared > max_bytes:
                raise ConfigError(f"{where}: its members declare {declared:,} bytes uncompressed, more than the "
                                  f"{max_bytes:,} allowed; refused before decompressing anything")
            out = {}
            for info in infos:
                if not info.filename.endswith(".npy"):
                    raise ConfigError(f"{where}: member {info.filename!r} is not a .npy array")
                name = info.filename[:-4]
                with zf.open(info) as fp:
                    shape, dtype = _npy_header(fp, f"{where}: member {name!r}")
                need = int(np.prod(shape, dtype=np.float64)) * dtype.itemsize
                if need > info.file_size:
                    raise ConfigError(f"{where}: member {name!r} declares shape {shape} of {dtype} ({need:,} bytes) "
                                      f"but holds {info.file_size:,} bytes")
                kinds = TEXT_KINDS if name in text_keys else NUMERIC_KINDS
                if dtype.kind not in kinds:
                    what = "text" if name in text_keys else "real numbers (float or int)"
                    raise ConfigError(f"{where}: member {name!r} has dtype {dtype}; it must hold {what} (complex, "
                                      "datetime, bytes, bool and object arrays are refused)")
                out[name] = (shape, dtype)
            return out
    except ConfigError:
        raise
    except ARCHIVE_ERRORS as exc:
        raise ConfigError(f"{where}: not a readable .npz archive ({type(exc).__name__}: {exc})") from None


def _npy_header(fp, where: str) -> tuple[tuple, np.dtype]:
    try:
        version = np.lib.format.read_magic(fp)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fp)
        elif version in ((2, 0), (3, 0)):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fp)
        else:
            raise ValueError(f"unsupported .npy version {version}")
    except (ValueError, EOFError, SyntaxError, TypeError) as exc:
        raise ConfigError(f"{where}: not a .npy array ({exc})") from None
    return tuple(int(n) for n in shape), np.dtype(dtype)


def read_arrays(path) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` file ``path`` (no pickles), after :func:`declared_arrays`
    accepted it; ConfigError on a bad CRC, a truncated member or any other archive error."""
    p = Path(path)
    try:
        with np.load(p, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except ARCHIVE_ERRORS as exc:
        raise ConfigError(f"npz file {str(p)!r}: not a readable .npz archive ({type(exc).__name__}: {exc})") from None
