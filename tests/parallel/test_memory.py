"""Freed fields go back to the system once petgap is imported (petgap.parallel.memory).

PETSc's SuperLU_DIST turns off glibc's mapping of large blocks and the trimming of
its heap as it loads; without :func:`return_freed_memory` a freed field stays
resident.  Measured on this process's ``VmRSS`` (Linux), per rank.
"""
import importlib
import sys

import numpy as np
import pytest

from petgap.parallel.memory import mallopt, return_freed_memory

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"),
                                reason="reads /proc/self/status and glibc's mallopt")

MIB = 2**20


def resident():
    with open("/proc/self/status") as status:
        for line in status:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS in /proc/self/status")


def released_after_free(nbytes=64 * MIB):
    """Bytes of a touched ``nbytes`` block that leave the resident set when it is freed."""
    block = np.ones(nbytes // 8)
    held = resident()
    del block
    return held - resident()


def test_a_freed_field_leaves_the_resident_set():
    # importing petgap loads PETSc (and SuperLU_DIST's constructor), then makes the call
    importlib.import_module("petgap")
    assert "petsc4py.PETSc" in sys.modules
    assert released_after_free() > 48 * MIB


def test_the_settings_are_what_petgap_import_restores():
    # undo them as SuperLU_DIST does, see the field stay, restore, see it go
    set_option = mallopt()
    assert set_option(-4, 0) == 1 and set_option(-1, -1) == 1   # M_MMAP_MAX, M_TRIM_THRESHOLD
    try:
        stays = released_after_free()
    finally:
        assert return_freed_memory()
    assert stays < 16 * MIB
    assert released_after_free() > 48 * MIB
