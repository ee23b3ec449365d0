"""Rough surfaces: generated self-affine ones and measured ones, and their spectral statistics.

A surface is a slab of heights ``h`` on a :class:`~petgap.parallel.grid.Grid`,
shape ``grid.local_shape``, in the grid's length unit; no rank ever holds the
global field.

Modules
-------
:mod:`.self_affine`
    :func:`~petgap.surfaces.self_affine.self_affine`: periodic Gaussian surfaces
    with the paper's Eq. 5 spectrum (:func:`psd_shape`), drawn on each rank's own
    Fourier rows from counter-based random streams (the same seed gives the same
    surface on any number of ranks).
:mod:`.statistics`
    :func:`~petgap.surfaces.statistics.statistics` (mean, rms height, slope and
    curvature, spectrally; the scales of every unit-free residual) and
    :func:`radial_psd`.
:mod:`.resampling`
    A surface's band-limited spectrum carried to another grid (``petgap study``'s
    resolution ladder).
:mod:`.topography`
    :func:`load_topography` reads a global ``.npy`` or HDF5 array straight into
    each rank's slab; :func:`save_topography_npy` writes one.
:mod:`.measured`
    :func:`read_measured` reads an instrument's file with SurfaceTopography, with its
    physical size, unit and periodicity (:class:`Measurement`).

The generator and the statistics are imported from their modules
(``from petgap.surfaces.self_affine import self_affine``,
``from petgap.surfaces.statistics import statistics``) or from :mod:`petgap`:
this package does not re-export them, so that ``petgap.surfaces.self_affine``
and ``petgap.surfaces.statistics`` stay the modules.
"""
from petgap.surfaces.self_affine import psd_shape
from petgap.surfaces.statistics import SurfaceStatistics, radial_psd
from petgap.surfaces.measured import Measurement, read_measured
from petgap.surfaces.topography import load_topography, save_topography_npy

__all__ = ["SurfaceStatistics", "psd_shape", "radial_psd", "load_topography",
           "save_topography_npy", "read_measured", "Measurement"]
