"""Rough surfaces: generated self-affine ones and measured ones, and their spectral statistics.

A surface is a slab of heights ``h`` on a :class:`~petgap.parallel.grid.Grid`,
shape ``grid.local_shape``, in the grid's length unit; no rank ever holds the
global field.

Modules
-------
:mod:`.self_affine`
    :func:`~petgap.surfaces.self_affine.self_affine`: periodic Gaussian surfaces
    with the paper's Eq. 5 spectrum, drawn on each rank's own Fourier rows from
    counter-based random streams (the same seed gives the same surface on any
    number of ranks); :func:`statistics` (mean, rms height, slope and
    curvature, spectrally) and :func:`radial_psd`.
:mod:`.topography`
    :func:`load_topography` reads a global ``.npy`` or HDF5 array straight into
    each rank's slab; :func:`save_topography_npy` writes one.

The generator is imported as ``from petgap.surfaces.self_affine import
self_affine`` (or ``petgap.self_affine``): this package does not re-export it,
so that ``petgap.surfaces.self_affine`` stays the module.
"""
from petgap.surfaces.self_affine import SurfaceStatistics, psd_shape, radial_psd, statistics
from petgap.surfaces.topography import load_topography, save_topography_npy

__all__ = ["SurfaceStatistics", "psd_shape", "radial_psd", "statistics", "load_topography",
           "save_topography_npy"]
