"""Process memory: freed fields go back to the system.

Why: Debian's PETSc links SuperLU_DIST, whose library constructor calls
``mallopt(M_MMAP_MAX, 0)`` and ``mallopt(M_TRIM_THRESHOLD, -1)`` as it loads.
From then on glibc serves every allocation, however large, from the one
``brk`` heap and never gives memory back: a field freed after one phase of a
run (the double-precision surface of a single-precision scene, the coarse
levels of a start) stays resident, and a later field that does not fit a
hole grows the heap past the live total.  The peak resident memory of a run
is then its largest heap, not its largest live set.

:func:`return_freed_memory` restores allocation by ``mmap`` for large blocks
(each field its own mapping, unmapped when freed) and trimming of the heap's
free top.  petgap calls it once, when it is imported, after PETSc has loaded;
nothing in petgap uses SuperLU_DIST.  On a C library without ``mallopt``
(not glibc) it does nothing.
"""
import ctypes
import importlib

# glibc's <malloc.h> parameter numbers
_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_M_MMAP_MAX = -4

#: Blocks from this size up get a mapping of their own (a 1024^2 float32 field
#: is 4 MiB); smaller ones stay on the heap, where reusing them is cheap.
MMAP_THRESHOLD = 4 * 2**20
#: The heap's free top above this size is returned to the system (glibc's
#: own ratio to the threshold).
TRIM_THRESHOLD = 2 * MMAP_THRESHOLD
#: glibc's default limit on the number of mapped blocks.
MMAP_MAX = 65536


def mallopt():
    """glibc's ``mallopt(parameter, value)`` (1 on success), or None without one.

    Looked up among the symbols the process has already loaded: no library search.
    """
    try:
        function = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return None
    function.argtypes = [ctypes.c_int, ctypes.c_int]
    function.restype = ctypes.c_int
    return function


def return_freed_memory():
    """Let glibc map large blocks and trim its heap again; True if it could.

    Loads PETSc first (``petsc4py.PETSc``: its libraries' constructors run on
    load), so that nothing loaded later by petgap undoes the settings.
    Process-local; safe to call more than once.
    """
    # deferred to the call (importing petsc4py initialises PETSc): loaded here for its
    # libraries' constructors
    importlib.import_module("petsc4py.PETSc")
    set_option = mallopt()
    if set_option is None:
        return False
    settings = ((_M_MMAP_MAX, MMAP_MAX), (_M_MMAP_THRESHOLD, MMAP_THRESHOLD),
                (_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
    return all([set_option(parameter, value) == 1 for parameter, value in settings])
