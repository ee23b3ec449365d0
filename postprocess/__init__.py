"""Post-processing of petgap result files: the paper's tables and figures.

:mod:`postprocess.cli` is the ``petgap-post`` command; the analysis itself lives
in :mod:`petgap.analysis`, so that it can be called on fields in memory as well.
"""
