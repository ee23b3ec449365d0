"""petgap: gap distributions and adhesion between rough elastic surfaces.

The package follows the data flow of a run: scene -> grid -> surface -> problem
(elastic half-space + interaction) -> TAO solve -> fields -> HDF5 -> post-processing.
Importing it has no side effect beyond loading its modules; MPI, PETSc and
FFTW-MPI are initialised by the modules that need them.
"""
__version__ = "0.1.0"
