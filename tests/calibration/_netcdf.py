"""Editing a saved calibration file as a hostile or older writer would."""

import xarray as xr


def rewrite_netcdf(src, dst, edit):
    """Load ``src`` with xarray, change it with ``edit(ds)``, write the result to ``dst`` (netCDF4)."""
    with xr.open_dataset(src, engine="h5netcdf") as ds:
        ds = edit(ds.load())
    ds.to_netcdf(dst, engine="h5netcdf")
    return dst
