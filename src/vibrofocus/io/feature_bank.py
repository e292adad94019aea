"""Feature-bank files (``.npz``): felt energies of every study stimulus on simulated forearms.

Arrays: ``energy`` (n_forearms, n_methods, n_locations, n_points), float32, felt energy
re the reference tap; ``points_xy`` (n_points, 2), m; ``locations_xy`` (n_locations, 2),
m; ``centre_xy`` (2,), m; ``methods`` (n_methods,), str; ``forearm_seeds``
(n_forearms,), int; ``seed`` (scalar), int; ``actuator_energy`` (n_forearms,
n_methods, n_locations, n_actuators), float32, each actuator's own felt energy at its
contact; ``actuators_xy`` (n_actuators, 2), m; ``model_version`` (scalar), str: the
perceptual model that wrote it; ``levels`` (scalar), str: the level rule the stimuli were
rendered with (a bank written before it was stored: ``equal-peak``); ``drive_peak_v``
(n_forearms, n_methods, n_locations), V, and ``target_peak_m`` (the same shape), m: each
stimulus's largest |drive| and its peak at the target predicted from the calibration
(absent in a bank written before them). The shipped bank is ``simulation/data/feature_bank.npz``
(``scripts/build_feature_bank.py``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ValidationError

__all__ = ["FEATURE_BANK_ARRAYS", "FEATURE_BANK_OPTIONAL", "save_feature_bank", "load_feature_bank"]

#: The arrays of a feature bank, as :func:`save_feature_bank` takes them and
#: :func:`load_feature_bank` returns them (besides ``model_version``).
FEATURE_BANK_ARRAYS = ("energy", "points_xy", "locations_xy", "centre_xy", "methods", "forearm_seeds", "seed",
                       "actuator_energy", "actuators_xy")
#: Optional entries (``levels``, then the stimulus peaks): a bank without them is read
#: with ``levels="equal-peak"`` and no peaks (None).
FEATURE_BANK_OPTIONAL = ("levels", "drive_peak_v", "target_peak_m")


def save_feature_bank(bank: Mapping[str, Any], path: str | os.PathLike, *, model_version: str) -> Path:
    """Write a feature bank's arrays to an ``.npz`` file, atomically (:func:`vibrofocus._atomic.atomic_write`).

    Parameters
    ----------
    bank : mapping
        The arrays named :data:`FEATURE_BANK_ARRAYS` (see the module docstring for shapes
        and units), e.g. ``dataclasses.asdict`` of a
        :class:`~vibrofocus.simulation.bank.FeatureBank`.
    path : path-like
        Destination ``.npz``; its folder must exist.
    model_version : str
        Version of the perceptual model the energies were computed with.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OutputError
        The file cannot be written; a previous file at ``path`` is unchanged.
    """
    from .._atomic import atomic_write

    missing = [name for name in FEATURE_BANK_ARRAYS if name not in bank]
    if missing:
        raise ValidationError(f"a feature bank needs the arrays {', '.join(missing)}")
    extra = {name: np.asarray(bank[name]) for name in FEATURE_BANK_OPTIONAL if bank.get(name) is not None}
    with atomic_write(path, "wb", what="feature bank") as fh:
        np.savez_compressed(
            fh, **extra, energy=np.asarray(bank["energy"]).astype(np.float32), points_xy=bank["points_xy"],
            locations_xy=bank["locations_xy"], centre_xy=bank["centre_xy"], methods=np.array(bank["methods"]),
            forearm_seeds=bank["forearm_seeds"], seed=np.int64(bank["seed"]),
            actuator_energy=np.asarray(bank["actuator_energy"]).astype(np.float32), actuators_xy=bank["actuators_xy"],
            model_version=np.array(model_version),
        )
    return Path(path)


def load_feature_bank(path: str | os.PathLike) -> dict[str, Any]:
    """Read and check a feature bank's arrays written by :func:`save_feature_bank`.

    The file is untrusted: the arrays' npy headers are read first and checked against
    the bytes the archive holds and against a cap from the file's size
    (:mod:`vibrofocus.io._headers`), before any array is decompressed; then the arrays
    are checked against each other and for their values.

    Parameters
    ----------
    path : path-like
        A feature-bank ``.npz``.

    Returns
    -------
    dict
        :data:`FEATURE_BANK_ARRAYS` and :data:`FEATURE_BANK_OPTIONAL`: ``energy`` float,
        ``methods`` a tuple of str, ``seed`` an int, ``levels`` a str, the others arrays
        (the peaks None when absent); ready for ``FeatureBank(**...)``.

    Raises
    ------
    ValidationError
        Naming the file and the problem: missing, a folder or not an npz; a missing
        array; a header claiming more than the file holds, or more than the cap; shapes
        that disagree (energy (n_forearms, n_methods, n_locations, n_points) with at
        least one of each, and the positions and seeds to match); NaN/Inf or negative
        energies; NaN/Inf positions; method names that are not distinct texts.
    """
    import zipfile

    from .._atomic import protect
    from .._validation import shorten
    from ._headers import declared_cap, npy_member_header

    path = Path(path)
    what = f"feature bank {path}"
    protect(path, "feature bank")
    if path.is_dir():
        raise ValidationError(f"{what}: it is a folder; give the .npz written by scripts/build_feature_bank.py")
    if not path.is_file():
        raise ValidationError(f"{what}: no such file")
    try:
        with open(path, "rb") as fh:
            head = fh.read(4)
        if head[:2] != b"PK":  # an .npz is a zip archive
            raise ValidationError(f"{what}: not an .npz file (it does not start as a zip archive)")
        with zipfile.ZipFile(path) as zf:
            held = [n.removesuffix(".npy") for n in zf.namelist()]
            missing = [k for k in FEATURE_BANK_ARRAYS if k not in held]
            if missing:
                raise ValidationError(f"{what}: missing array(s) {', '.join(missing)} (it holds "
                                      f"{shorten(', '.join(held) or 'nothing', 200, as_text=True)})")
            headers = {k: npy_member_header(zf, f"{k}.npy", what) for k in FEATURE_BANK_ARRAYS}
            headers.update({k: npy_member_header(zf, f"{k}.npy", what) for k in FEATURE_BANK_OPTIONAL if k in held})
        total, cap = sum(h[2] for h in headers.values()), declared_cap(path.stat().st_size)
        if total > cap:
            raise ValidationError(f"{what}: its arrays declare {total:,} bytes in all, more than a feature bank of "
                                  f"{path.stat().st_size:,} bytes may ({cap:,} bytes); refused before reading")
        for k, (shape, dtype, _) in headers.items():
            wanted = "U" if k in ("methods", "levels") else ("iu" if k in ("forearm_seeds", "seed") else "iuf")
            if dtype.kind not in wanted:
                raise ValidationError(f"{what}: {k} has dtype {dtype}, expected "
                                      f"{'texts' if k == 'methods' else 'integers' if wanted == 'iu' else 'numbers'}")
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in headers}
    except ValidationError:
        raise
    except (OSError, KeyError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ValidationError(f"{what}: not a readable .npz file ({str(exc)[:200]})") from None
    return _check_bank(arrays, what)


def _check_bank(z: Mapping[str, np.ndarray], what: str) -> dict[str, Any]:
    """The bank's arrays checked against each other and for their values (ValidationError naming them)."""
    from .._validation import as_array, check_nonnegative, check_shape

    energy = as_array(z["energy"], f"{what}: energy", ndim=4)
    n_f, n_m, n_l, n_p = energy.shape
    for n, axis in zip(energy.shape, ("forearm", "method", "location", "point")):
        if n < 1:
            raise ValidationError(f"{what}: energy has shape {energy.shape}, no {axis}; a bank needs at least one "
                                  "of each")
    check_nonnegative(energy, f"{what}: energy")
    own = as_array(z["actuator_energy"], f"{what}: actuator_energy", ndim=4)
    check_shape(own, f"{what}: actuator_energy", (n_f, n_m, n_l, None))
    check_nonnegative(own, f"{what}: actuator_energy")
    n_a = own.shape[3]
    if n_a < 1:
        raise ValidationError(f"{what}: actuator_energy has shape {own.shape}, no actuator")
    points = as_array(z["points_xy"], f"{what}: points_xy", shape=(n_p, 2))
    locations = as_array(z["locations_xy"], f"{what}: locations_xy", shape=(n_l, 2))
    centre = as_array(z["centre_xy"], f"{what}: centre_xy", shape=(2,))
    actuators = as_array(z["actuators_xy"], f"{what}: actuators_xy", shape=(n_a, 2))
    seeds = np.asarray(z["forearm_seeds"])
    check_shape(seeds, f"{what}: forearm_seeds", (n_f,))
    seed = np.asarray(z["seed"])
    check_shape(seed, f"{what}: seed", ())
    methods = np.asarray(z["methods"])
    check_shape(methods, f"{what}: methods", (n_m,))
    names = tuple(str(m) for m in methods)
    if any(not m.strip() for m in names) or len(set(names)) != len(names):
        raise ValidationError(f"{what}: methods must be {n_m} distinct names, got {list(names)}")
    levels = np.asarray(z["levels"]) if "levels" in z else np.asarray("equal-peak")
    check_shape(levels, f"{what}: levels", ())
    peaks = {}
    for k in ("drive_peak_v", "target_peak_m"):
        if k in z:
            peaks[k] = as_array(z[k], f"{what}: {k}", shape=(n_f, n_m, n_l))
            check_nonnegative(peaks[k], f"{what}: {k}")
        else:
            peaks[k] = None
    return {"energy": energy, "points_xy": points, "locations_xy": locations, "centre_xy": centre,
            "methods": names, "forearm_seeds": seeds.astype(np.int64), "seed": int(seed),
            "actuator_energy": own, "actuators_xy": actuators, "levels": str(levels), **peaks}
