"""Collective decisions: one rank decides, every rank acts on the same verdict.

Checks that touch the file system (does the file exist? is it a petgap file?)
must give the same answer on every rank, or one rank raises while the others
wait in the next collective call and the job hangs.  Rank 0 decides; the value,
or the exception, reaches every rank.
"""


def root_decides(comm, func):
    """Run ``func()`` on rank 0; return its value everywhere, or raise its exception everywhere."""
    result = None
    if comm.rank == 0:
        try:
            result = ("ok", func())
        except Exception as exc:  # re-raised on every rank below
            result = ("error", exc)
    status, value = comm.bcast(result, root=0)
    if status == "error":
        raise value
    return value
