"""The package layout is the data flow: imports point down it, without cycles, in plain sight.

Read from the source with :mod:`ast` (module-level and function-level imports
alike), nothing is imported:

* no import cycle between modules;
* imports between subpackages only point down the data flow
  ``parallel < (io, surfaces) < mechanics < solvers < analysis < flow < app``;
  ``reference_solutions`` imports nothing of petgap and anyone may import it;
  ``io.scene`` imports only the collective helpers (its file is read on rank 0
  and broadcast); a subpackage's ``__init__`` may import
  its own modules and the top-level ``petgap/__init__.py`` anything, while a
  module imports from the top level only what it defines before its own imports
  (``__version__``);
* every ``petgap`` import names a module that exists and a name it defines;
* a function-local import says why it is deferred (a comment containing
  "defer" on its line, or just above it or above the run of imports it is in);
* the README's layout section lists every subpackage.
"""
import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "petgap"

#: Position of each subpackage in the data flow; imports only go to a lower rank.
RANK = {"parallel": 0, "io": 1, "surfaces": 1, "mechanics": 2, "solvers": 3, "analysis": 4,
        "flow": 5, "app": 6}
#: Importable by any subpackage; imports nothing of petgap.
FREE = "reference_solutions"
#: Top-level modules that import nothing of petgap and that every module may import.
LEAVES = {"petgap._version"}
#: Modules allowed fewer petgap imports than their subpackage's rank gives them: the ones named.
RESTRICTED = {"petgap.io.scene": {"petgap.parallel.collective"}}


def module_name(path):
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def discover():
    """``{module name: path}`` of every Python and Cython module under petgap/."""
    modules = {}
    for path in sorted(PACKAGE.rglob("*")):
        if path.suffix in (".py", ".pyx") and ".venv" not in path.parts \
                and "__pycache__" not in path.parts:
            modules[module_name(path)] = path
    return modules


MODULES = discover()
SUBPACKAGES = sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py"))


class Import:
    """One import statement's target as seen from ``source``."""

    def __init__(self, source, line, target, names, local):
        self.source, self.line, self.target, self.names, self.local = (
            source, line, target, names, local)

    def __repr__(self):
        where = "function-local " if self.local else ""
        return f"{self.source}:{self.line} {where}import of {self.target} {self.names or ''}"


def _absolute(source, node):
    """The absolute module of an ImportFrom (relative imports resolved against ``source``)."""
    if not node.level:
        return node.module
    package = source.split(".")
    if not MODULES[source].name == "__init__.py":
        package = package[:-1]
    base = package[:len(package) - node.level + 1]
    return ".".join(base + ([node.module] if node.module else []))


def imports_of(source):
    """Every petgap import of module ``source``, with whether it sits inside a function."""
    path = MODULES[source]
    if path.suffix == ".pyx":  # Cython: only plain Python import lines can name petgap
        found = []
        for number, text in enumerate(path.read_text().splitlines(), 1):
            match = re.match(r"\s*(?:from\s+(petgap[\w.]*)\s+c?import\s+([\w, ]+)|"
                             r"c?import\s+(petgap[\w.]*))", text)
            if match:
                target = match.group(1) or match.group(3)
                names = [n.strip().split(" as ")[0] for n in (match.group(2) or "").split(",")
                         if n.strip()]
                found.extend(_edges(source, number, target, names, text[0].isspace()))
        return found
    tree = ast.parse(path.read_text(), filename=str(path))
    found = []

    def visit(node, local):
        for child in ast.iter_child_nodes(node):
            inside = local or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                 ast.Lambda))
            if isinstance(child, ast.Import):
                for alias in child.names:
                    found.extend(_edges(source, child.lineno, alias.name, [], local))
            elif isinstance(child, ast.ImportFrom):
                target = _absolute(source, child)
                found.extend(_edges(source, child.lineno, target,
                                    [a.name for a in child.names], local))
            visit(child, inside)

    visit(tree, False)
    return found


def _edges(source, line, target, names, local):
    """``from target import names`` as imports of modules: a name that is a submodule is one."""
    if not (target == "petgap" or target.startswith("petgap.")):
        return []
    plain = [n for n in names if f"{target}.{n}" not in MODULES]
    edges = [Import(source, line, f"{target}.{n}", [], local) for n in names
             if f"{target}.{n}" in MODULES]
    if plain or not names:
        edges.append(Import(source, line, target, plain, local))
    return edges


IMPORTS = {name: imports_of(name) for name in MODULES}


def subpackage(module):
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else None


def defined_names(module):
    """Names bound at the top level of ``module`` (None: cannot tell, accept any)."""
    path = MODULES[module]
    if path.suffix != ".py":
        return None
    names = set()

    def targets(node):
        if isinstance(node, ast.Name):
            names.add(node.id)
        elif isinstance(node, (ast.Tuple, ast.List)):
            for element in node.elts:
                targets(element)

    def visit(body):
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                names.add(node.name)
            elif isinstance(node, ast.Assign):
                for target in node.targets:
                    targets(target)
            elif isinstance(node, (ast.AnnAssign, ast.AugAssign)):
                targets(node.target)
            elif isinstance(node, (ast.Import, ast.ImportFrom)):
                for alias in node.names:
                    if alias.name == "*":
                        return True
                    names.add(alias.asname or alias.name.split(".")[0])
            elif isinstance(node, (ast.For, ast.AsyncFor)):
                targets(node.target)
            for field in ("body", "orelse", "finalbody", "handlers"):
                inner = getattr(node, field, None)
                if isinstance(inner, list) and not isinstance(
                        node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    if visit(inner):
                        return True
        return False

    if visit(ast.parse(path.read_text()).body):
        return None
    return names


def early_root_names():
    """What ``petgap/__init__.py`` defines before its first import: safe to import from it."""
    names = set()
    for node in ast.parse((PACKAGE / "__init__.py").read_text()).body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            break
        if isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
    return names


# ---------------------------------------------------------------------- tests
def test_the_walk_sees_the_package():
    """The graph is not vacuous: the modules and their imports were found."""
    assert {"petgap", "petgap.parallel.grid", "petgap.solvers.dispatch",
            "petgap.parallel._fftw_mpi"} <= set(MODULES)
    assert any(i.target == "petgap.parallel.grid" for i in IMPORTS["petgap.parallel"])
    assert len(SUBPACKAGES) >= 8


def test_imports_resolve():
    """Every petgap import names an existing module, and a name that module defines."""
    problems = []
    for imports in IMPORTS.values():
        for imp in imports:
            if imp.target not in MODULES:
                problems.append(f"{imp}: no such module")
                continue
            defined = defined_names(imp.target)
            if defined is not None:
                problems.extend(f"{imp}: {imp.target} does not define {n}"
                                for n in imp.names if n not in defined)
    assert not problems, "\n".join(problems)


def find_cycles(graph):
    """The strongly connected components with more than one module (or a self-import)."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def connect(v):  # Tarjan's algorithm
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or v in graph.get(v, ()):
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    return cycles


def test_find_cycles_finds_cycles():
    assert find_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert find_cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles():
    """No module imports, directly or through others, a module that imports it.

    The top-level ``petgap/__init__.py`` is left out: it imports everything by
    design, and what modules take from it is checked by :func:`test_imports_point_down`.
    """
    graph = {name: {i.target for i in imports if i.target != "petgap"}
             for name, imports in IMPORTS.items() if name != "petgap"}
    cycles = find_cycles(graph)
    detail = []
    for cycle in cycles:
        members = set(cycle)
        detail.append(" <-> ".join(cycle) + ":\n    " + "\n    ".join(
            repr(i) for m in cycle for i in IMPORTS[m] if i.target in members))
    assert not cycles, "import cycles:\n" + "\n".join(detail)


def direction_problem(imp, early):
    """Why ``imp`` goes against the data flow, or None if it does not."""
    source = imp.source
    a, b = subpackage(source), subpackage(imp.target)
    if source == "petgap" or imp.target in LEAVES:
        return None  # the public API imports anything; anything imports the leaves
    if b is None:
        late = [n for n in imp.names if n not in early]
        return (f"{imp}: the top-level package defines {late} only after importing the "
                f"subpackages") if late else None
    if source in RESTRICTED and b != a and imp.target not in RESTRICTED[source]:
        return (f"{imp}: {source} imports nothing of petgap outside {a} but "
                f"{sorted(RESTRICTED[source])}")
    if a == b or b == FREE:
        return None
    if a == FREE:
        return f"{imp}: {FREE} imports nothing of petgap"
    if RANK[b] >= RANK[a]:
        below = ", ".join(k for k, r in RANK.items() if r < RANK[a]) or "nothing"
        return f"{imp}: {a} may only import from before it in the data flow ({below}, {FREE})"
    return None


def test_direction_rule():
    """The rule itself, on made-up imports."""
    def problem(source, target, names=()):
        return direction_problem(Import(source, 1, target, list(names), False), {"__version__"})
    assert problem("petgap.solvers.dispatch", "petgap.mechanics.problem") is None
    assert problem("petgap.mechanics.problem", "petgap.solvers.dispatch")
    assert problem("petgap.surfaces.topography", "petgap.io.results")  # siblings
    assert problem("petgap.app.run", "petgap.reference_solutions") is None
    assert problem("petgap.reference_solutions.hertz", "petgap.parallel.grid")
    assert problem("petgap.io.scene", "petgap.parallel.grid")
    assert problem("petgap.io.results", "petgap.parallel.grid") is None
    assert problem("petgap.app.run", "petgap", ["__version__"]) is None
    assert problem("petgap.app.run", "petgap", ["solve"])
    assert problem("petgap", "petgap.app.run") is None
    assert problem("petgap.mechanics", "petgap.mechanics.problem") is None


def test_imports_point_down():
    """Imports between subpackages follow the data flow; reference_solutions stands alone."""
    early = early_root_names()
    problems = [direction_problem(imp, early) for imports in IMPORTS.values() for imp in imports]
    problems = [p for p in problems if p is not None]
    assert not problems, "\n".join(problems)


def _is_comment_with_defer(text):
    return "#" in text and "defer" in text[text.index("#"):].lower()


def undeferred_imports(text):
    """Line numbers of the function-local imports in ``text`` without a comment saying why.

    The comment (containing "defer") is on the import's own lines, or on the
    comment lines just above it, or above the run of imports it belongs to.
    """
    lines = text.splitlines()
    local_lines, nodes = set(), []

    def visit(node, local):
        for child in ast.iter_child_nodes(node):
            inside = local or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                 ast.Lambda))
            if local and isinstance(child, (ast.Import, ast.ImportFrom)):
                nodes.append(child)
                local_lines.update(range(child.lineno, child.end_lineno + 1))
            visit(child, inside)

    visit(ast.parse(text), False)
    bare = []
    for node in nodes:
        if any(_is_comment_with_defer(lines[k - 1])
               for k in range(node.lineno, node.end_lineno + 1)):
            continue
        k = node.lineno - 1
        while k >= 1 and k in local_lines and not _is_comment_with_defer(lines[k - 1]):
            k -= 1  # up through the run of imports this one belongs to
        while k >= 1 and lines[k - 1].strip().startswith("#") \
                and not _is_comment_with_defer(lines[k - 1]):
            k -= 1  # up through the comment block above it
        if not (k >= 1 and _is_comment_with_defer(lines[k - 1])):
            bare.append(node.lineno)
    return bare


def test_defer_rule():
    """The rule itself, on made-up source."""
    text = """\
import os


def a():
    # deferred: importing h5py picks its MPI build
    import h5py
    import numpy


def b():
    import numpy  # defer NumPy for a fast --help


def c():
    x = 1
    import numpy
    # a comment about something else
    import json


def d():
    # Defers MPI initialisation to the first call,
    # which the CLI makes after parsing its arguments.
    from mpi4py import (
        MPI)
"""
    assert undeferred_imports(text) == [16, 18]


def test_function_local_imports_say_why():
    """Each function-local import defers MPI/PETSc/h5py/matplotlib on purpose, and says so."""
    problems = []
    for path in MODULES.values():
        if path.suffix == ".py":
            text = path.read_text()
            problems.extend(f"{path.relative_to(ROOT)}:{k}: {text.splitlines()[k - 1].strip()}"
                            for k in undeferred_imports(text))
    assert not problems, ("function-local imports without a comment saying why they are "
                          "deferred:\n" + "\n".join(problems))


def readme_layout_block():
    """The first fenced block under the README heading that contains "Layout"."""
    lines = (ROOT / "README.md").read_text().splitlines()
    heading = next((k for k, line in enumerate(lines)
                    if line.startswith("#") and "layout" in line.lower()), None)
    assert heading is not None, "README.md has no heading containing 'Layout'"
    level = len(lines[heading]) - len(lines[heading].lstrip("#"))
    block, inside = [], False
    for line in lines[heading + 1:]:
        if not inside and line.startswith("#") and \
                len(line) - len(line.lstrip("#")) <= level:
            break
        if line.lstrip().startswith("```"):
            if inside:
                return "\n".join(block)
            inside = True
            continue
        if inside:
            block.append(line)
    pytest.fail("README.md's layout section has no fenced block")


def test_readme_layout_lists_every_subpackage():
    block = readme_layout_block()
    missing = [f"petgap/{name}/" for name in SUBPACKAGES if f"petgap/{name}/" not in block]
    assert not missing, f"README.md's layout block does not list {missing}"
