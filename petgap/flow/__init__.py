"""Flow through the gaps of a contact: the Reynolds equation on the gap field, leakage.

Modules: :mod:`.reynolds` (the finite-volume Reynolds equation on the pixels, assembled
over petgap's row slabs and solved with PETSc's CG and algebraic multigrid) and
:mod:`.leakage` (leak rate, transmissivity, flow factor, pressure and flux fields of a gap
field or a solved contact).  The open clusters and their percolation are
:func:`petgap.analysis.open_clusters`'s.

The flow follows the contact in the data flow: it reads the gap of a solution and the
analysis of its open region, and the applications (``petgap run``'s ``[flow]`` section,
``petgap-post``) read it.
"""
from petgap.flow.leakage import Leakage, leakage, leakage_of  # noqa: F401  (the package's API)
from petgap.flow.reynolds import OPTIONS_PREFIX, PC_TYPE, RTOL  # noqa: F401  (the package's API)

__all__ = ["Leakage", "leakage", "leakage_of", "OPTIONS_PREFIX", "PC_TYPE", "RTOL"]
