"""Declared array sizes read from file headers (HDF5, npz), checked before any data is read.

A header is a claim: an HDF5 dataset that was never written costs a few hundred bytes
on disk and reads back in full as its fill value; compressed zeros shrink a
thousandfold. Every reader of an HDF5 format (calibration netCDF, SOFA) or an ``.npz``
(drives, feature banks) checks the arrays it will read here first, through the one helper
:func:`vibrofocus._validation.check_declared_size`.

An HDF5 file can also point outside itself: a soft or external link, a dataset whose
bytes live in other files (external storage, a FIFO or ``/dev/zero`` included) or a
virtual dataset made of other files' datasets. :func:`check_hdf5_storage` refuses all of
them before any dataset is opened through a link or any data is read, so a file can only
give its own bytes.
"""

from __future__ import annotations

import os
from collections.abc import Collection
from pathlib import Path
from typing import Any

from ..errors import ValidationError

#: Largest total a file's read datasets may declare, bytes, whatever the file's size ...
DECLARED_FLOOR_BYTES = 256 * 2**20
#: ... and beyond it, at most this many times the file's size. The formats store raw
#: numbers that hardly compress (measured noise, transfer functions), so an honest file
#: declares about its own size; a few MB of file declaring GBs is compressed filler.
DECLARED_PER_FILE_BYTE = 16
#: HDF5 filters that keep the data's size: shuffle (2) and the Fletcher-32 checksum (3).
_SIZE_KEEPING_FILTERS = frozenset({2, 3})
#: How netCDF-4 marks an HDF5 dataset that is only a dimension (its NAME attribute).
_DIMENSION_ONLY = "This is a netCDF dimension but not a netCDF variable"


#: Most links an HDF5 file of these formats may hold (a calibration has a few dozen).
MAX_HDF5_LINKS = 10_000


def _name(value: Any) -> str:
    """A name HDF5 gives (bytes or str) as text, at most 200 characters."""
    return (os.fsdecode(value) if isinstance(value, bytes) else str(value))[:200]


def check_hdf5_storage(f: Any, what: str) -> None:
    """Refuse an HDF5 file that takes data from anywhere but its own bytes.

    Every link of the file is walked without following it: soft and external links
    (and user-defined ones) are refused, and every dataset must keep its data in the
    file (contiguous, chunked or compact layout, no external storage, not virtual).
    Only the object headers are read: no other file is opened and no data is read.

    Parameters
    ----------
    f : h5py.File
        The open file.
    what : str
        What the file is, for the message (``"a calibration file"``).

    Raises
    ------
    ValidationError
        Naming the link or dataset and where it points.
    """
    import h5py

    seen: set[Any] = set()
    count = 0

    def refuse(name: str, reason: str) -> ValidationError:
        return ValidationError(f"{name} {reason}; {what} must hold its own data, so it was refused before reading")

    def walk(group: Any, prefix: str) -> None:
        nonlocal count
        for key in group:  # names only: nothing is resolved
            name = f"{prefix}{key}"
            count += 1
            if count > MAX_HDF5_LINKS:
                raise ValidationError(f"it holds more than {MAX_HDF5_LINKS:,} HDF5 links, more than {what} has; "
                                      "refused before reading")
            link = group.get(key, getlink=True)
            if isinstance(link, h5py.SoftLink):
                raise refuse(name, f"is an HDF5 soft link (to {_name(link.path)!r})")
            if isinstance(link, h5py.ExternalLink):
                raise refuse(name, f"is an HDF5 external link (to {_name(link.path)!r} in the file "
                                   f"{_name(link.filename)!r})")
            if not isinstance(link, h5py.HardLink):
                raise refuse(name, "is an HDF5 link of a user-defined kind")
            obj = group[key]
            if obj.id in seen:  # a group reached twice (hard links may loop)
                continue
            seen.add(obj.id)
            if isinstance(obj, h5py.Group):
                walk(obj, f"{name}/")
            elif isinstance(obj, h5py.Dataset):
                plist = obj.id.get_create_plist()
                if plist.get_layout() == h5py.h5d.VIRTUAL:
                    raise refuse(name, "is an HDF5 virtual dataset (its data come from other files)")
                if plist.get_external_count():
                    files = sorted({_name(plist.get_external(k)[0]) for k in range(plist.get_external_count())})
                    raise refuse(name, f"keeps its data outside the file (HDF5 external storage in {', '.join(files)})")

    walk(f, "")


def declared_cap(file_bytes: int) -> int:
    """Most the read datasets of a file of ``file_bytes`` bytes may declare in all, bytes."""
    return max(DECLARED_FLOOR_BYTES, DECLARED_PER_FILE_BYTE * int(file_bytes))


def check_hdf5_sizes(path: Path, what: str, known: Collection[str] | None = None
                     ) -> tuple[dict[str, tuple[int, ...]], list[str]]:
    """Check the declared sizes of a netCDF-4/HDF5 file's root datasets from its header.

    Each dataset that will be read (all of them, or those named in ``known``) must fit in
    the bytes the file stores for it (compressed: up to
    :data:`vibrofocus._validation.MAX_EXPANSION` times them), and all of them together in
    :func:`declared_cap` of the file's size.

    Parameters
    ----------
    path : Path
        The file (already known to start with the HDF5 signature).
    what : str
        What the file is, for the message (``"a calibration file"``).
    known : collection of str, optional
        The variables the reader reads; others are not checked and are returned.

    Returns
    -------
    shapes : dict
        Declared shape of each checked dataset.
    unknown : list of str
        Datasets not in ``known`` (netCDF dimensions without a variable left out).

    Raises
    ------
    ValidationError
        A link or a dataset stored outside the file (:func:`check_hdf5_storage`), a
        dataset declared larger than the file can hold, or the total above the cap.
    OSError
        The HDF5 library cannot read the header.
    """
    import h5py

    from .._validation import check_declared_size

    file_bytes = path.stat().st_size
    cap = declared_cap(file_bytes)
    shapes: dict[str, tuple[int, ...]] = {}
    unknown: list[str] = []
    total = 0
    with h5py.File(path, "r") as f:
        check_hdf5_storage(f, what)  # first: items() below would follow links
        for name, obj in f.items():
            if not isinstance(obj, h5py.Dataset):
                continue
            label = obj.attrs.get("NAME", b"")
            label = label.decode("latin-1") if isinstance(label, bytes) else str(label)
            if label.startswith(_DIMENSION_ONLY):
                continue  # a netCDF dimension without a variable: no data
            if known is not None and name not in known:
                unknown.append(name)
                continue
            shapes[name] = tuple(int(n) for n in (obj.shape or ()))
            plist = obj.id.get_create_plist()
            filters = {plist.get_filter(k)[0] for k in range(plist.get_nfilters())}
            total += check_declared_size(shapes[name], obj.dtype.itemsize, f"variable {name}",
                                         stored_bytes=obj.id.get_storage_size(),
                                         compressed=bool(filters - _SIZE_KEEPING_FILTERS))
    if total > cap:
        raise ValidationError(f"its variables declare {total:,} bytes in all, more than {what} of {file_bytes:,} "
                              f"bytes may ({cap:,} bytes: the larger of {DECLARED_FLOOR_BYTES // 2**20} MiB and "
                              f"{DECLARED_PER_FILE_BYTE} x the file's size); refused before reading")
    return shapes, unknown


def npy_member_header(zf: Any, name: str, what: str) -> tuple[tuple[int, ...], Any, int]:
    """Shape, dtype and data size (bytes) of member ``name`` of an ``.npz``, from its header alone.

    Nothing but the header is decompressed. The header's shape must match the size the
    archive's directory gives for the member, and fit in the bytes the archive stores
    for it (:func:`vibrofocus._validation.check_declared_size`), so a header that claims
    more data than the file holds is refused here, before anything is allocated.

    Parameters
    ----------
    zf : zipfile.ZipFile
        The open archive.
    name : str
        The member (``"drives.npy"``).
    what : str
        The file, for the message (``"drives file d.npz"``).

    Returns
    -------
    shape : tuple of int
    dtype : numpy.dtype
    n_bytes : int

    Raises
    ------
    ValidationError
        The header and the data disagree, or the data would not fit in memory.
    ValueError
        An npy format version numpy does not know, or an unreadable header.
    """
    import zipfile

    import numpy as np

    from .._validation import check_declared_size

    info = zf.getinfo(name)
    with zf.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise ValueError(f"npy format version {version} of {name}")
        header_bytes = fh.tell()
    shape = tuple(int(n) for n in shape)
    count = 1
    for n in shape:
        count *= n
    data_bytes = count * dtype.itemsize
    if data_bytes != info.file_size - header_bytes:
        raise ValidationError(
            f"{what}: the header of {name} claims shape {shape} ({data_bytes:,} bytes of {dtype}) but the file "
            f"holds {max(info.file_size - header_bytes, 0):,} bytes for it; the file is corrupt or was not written "
            "by numpy"
        )
    check_declared_size(shape, dtype.itemsize, f"{what}: {name}", stored_bytes=info.compress_size,
                        compressed=info.compress_type != zipfile.ZIP_STORED)
    return shape, dtype, data_bytes
