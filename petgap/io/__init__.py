"""What goes in and out of a run: the scene that describes it and the result file it writes.

Modules
-------
:mod:`.scene`
    :class:`Scene`: one TOML file per run, validated against a schema declared
    once (:func:`describe_schema`); every error is a :class:`SceneError` naming
    the key, the value and what is allowed, raised alike on every rank.
:mod:`.results`
    :class:`~petgap.io.results.ResultFile`: one HDF5 file per run, one global
    dataset per field written collectively by hyperslab, provenance and every
    step's solver status as attributes.  It is not imported here: importing it
    loads h5py (with ``H5PY_ALWAYS_USE_MPI`` set first, so that Debian's h5py
    picks its MPI build); ``import petgap.io.results`` when you need it.
"""
from petgap.io.scene import Scene, SceneError, describe_schema

__all__ = ["Scene", "SceneError", "describe_schema"]
