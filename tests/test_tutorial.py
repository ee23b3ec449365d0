"""``docs/tutorial.md`` runs: its Python blocks, in order, in one namespace, on every rank.

So the tutorial cannot drift from the API.  The blocks run in a directory
shared by all ranks (``mpi_tmp_path``), where they write their files.
"""
import re
from pathlib import Path

import pytest

TUTORIAL = Path(__file__).resolve().parents[1] / "docs" / "tutorial.md"


def python_blocks(text):
    """The bodies of the fenced ```python blocks of a markdown text, in order."""
    return re.findall(r"^```python[ \t]*\n(.*?)^```[ \t]*$", text, flags=re.DOTALL | re.MULTILINE)


def test_python_blocks_are_found():
    text = "a\n```python\nx = 1\n```\n```sh\nls\n```\n```python\ny = 2\n\nz = 3\n```\n"
    assert python_blocks(text) == ["x = 1\n", "y = 2\n\nz = 3\n"]


def test_tutorial_runs(comm, mpi_tmp_path, monkeypatch):
    blocks = python_blocks(TUTORIAL.read_text())
    assert len(blocks) >= 6
    monkeypatch.chdir(mpi_tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace = {"__name__": "__tutorial__"}
    for k, block in enumerate(blocks, 1):
        try:
            exec(compile(block, f"{TUTORIAL.name}, block {k}", "exec"), namespace)
        except Exception as exc:
            pytest.fail(f"block {k} of {TUTORIAL.name} raised {type(exc).__name__}: {exc}\n"
                        f"{block}")
    comm.Barrier()
    # What the blocks promise: the one-call result and the figure.
    assert namespace["result"].converged
    assert (mpi_tmp_path / "surface.npy").is_file()
    assert (mpi_tmp_path / "tutorial.png").stat().st_size > 0
