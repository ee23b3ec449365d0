"""Bad input and faults, met the way a user meets them: ``petgap run`` in a subprocess.

Pass criteria, for every failure: a non-zero exit (2 for a user error), a message
naming the problem (once, without a traceback, for a user error), no hang (every
subprocess has a timeout), no process of the job left running, and no completed
result lost, truncated or overwritten.  For a run interrupted mid-sweep (SIGTERM to
``mpirun`` or to every rank, SIGKILL of one rank, a full disk): the steps marked
complete read back whole and equal an uninterrupted run's, and rerunning the same
command continues the run to the same final results.

The job is driven from rank 0 (the other pytest rank sleeps in
:func:`conftest.wait_for_root`), and every rank asserts on the outcome it is
handed.  To make an interruption land at a known place, the ranks are stopped
(SIGSTOP) when the progress log shows the trigger line, the signal is sent, and
the ranks are continued (by ``mpirun`` itself when it is the one signalled): a
signal delivered to a stopped process acts when it resumes, where it stopped.
"""
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from conftest import clean_env, shared_directory, wait_for_root
from petgap.io.results import FREE_SPACE_MARGIN, read_attrs

import h5py  # after petgap.io.results, which selects the MPI build  # noqa: E402

COMM = MPI.COMM_WORLD

# A 64^2 run of the paper's protocol: 4 non-adhesive steps, then 4 adhesive steps at
# the mean gaps the first found (so a resumed adhesive step reads its reference back).
SWEEP = """
[grid]
nx = 64

[surface]
hurst = 0.8
lambda_min = "8 a0"
seed = 3

[interaction]
kind = "exponential"
work_of_adhesion = 0.002
range = "1 a0"

[control]
kind = "load"
values = [0.001, 0.002, 0.004, 0.008]
reference = "non-adhesive"

[solver]
planner = "estimate"
"""
NSTEPS = 8
SHAPE = (64, 64)

SMALL = """
[grid]
nx = 32

[surface]
hurst = 0.8
lambda_min = "8 a0"
seed = 3

[control]
kind = "load"
values = [0.002, 0.004]

[solver]
planner = "estimate"
"""

FILE_SCENE = """
[grid]
nx = 32

[surface]
kind = "file"
path = "{path}"
{extra}
[control]
kind = "load"
values = [0.002]

[solver]
planner = "estimate"
"""


# ------------------------------------------------------------------ helpers
def _mpirun(args, ranks=2):
    return ["mpirun", "-n", str(ranks), "--oversubscribe"] + [str(a) for a in args]


def _alive(token):
    """Pids of live processes whose command line contains ``token`` (rank 0 only)."""
    out = subprocess.run(["pgrep", "-f", str(token)], capture_output=True, text=True).stdout
    pids = []
    for pid in map(int, out.split()):
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z" and pid != os.getpid():
            pids.append(pid)
    return pids


def _leftovers(token, grace=10.0):
    """Processes still running ``grace`` seconds after a job ended (rank 0 only)."""
    deadline = time.monotonic() + grace
    while _alive(token) and time.monotonic() < deadline:
        time.sleep(0.1)
    return _alive(token)


def _finish(proc, token, timeout):
    """Wait for a job; on timeout kill it and its ranks (by pid) and report a hang."""
    try:
        proc.wait(timeout=timeout)
        return False
    except subprocess.TimeoutExpired:
        for pid in [proc.pid] + _alive(token):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        proc.wait()
        return True


def run_many(jobs, timeout=60, parallel=3):
    """Run ``(args, token)`` jobs concurrently from rank 0; their outcomes on every rank.

    Each outcome: ``returncode``, ``stdout``, ``stderr``, ``hung`` and ``leftovers``
    (pids still running with ``token`` in their command line).
    """
    def one(job):
        args, token = job
        with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
            proc = subprocess.Popen(args, stdout=out, stderr=err, env=clean_env(),
                                    start_new_session=True)
            hung = _finish(proc, token, timeout)
            out.seek(0)
            err.seek(0)
            return {"returncode": proc.returncode, "stdout": out.read(), "stderr": err.read(),
                    "hung": hung, "leftovers": _leftovers(token)}

    def run():
        with ThreadPoolExecutor(parallel) as pool:
            return list(pool.map(one, jobs))
    return wait_for_root(run)


def _rank_pids(mpirun_pid, ranks, timeout=30.0):
    """``{rank: pid}`` of the processes ``mpirun`` started (its children)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        out = subprocess.run(["pgrep", "-P", str(mpirun_pid)], capture_output=True,
                             text=True).stdout
        found = {}
        for pid in map(int, out.split()):
            try:
                env = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
            except OSError:
                continue
            for item in env:
                if item.startswith(b"OMPI_COMM_WORLD_RANK="):
                    found[int(item.split(b"=")[1])] = pid
        if len(found) == ranks:
            return found
        time.sleep(0.01)
    raise RuntimeError(f"could not find the {ranks} ranks of mpirun {mpirun_pid}")


def interrupt(args, workdir, trigger, action, token, timeout=90, env=None):
    """Start ``mpirun -n 2 args``; when ``trigger`` shows in its log, stop the ranks, do
    ``action`` (``"term-mpirun"``, ``"term-ranks"`` or ``"kill-rank1"``), continue them.

    Runs on rank 0 (inside :func:`wait_for_root`).  Returns the job's outcome.
    """
    log_out, log_err = workdir / f"{token}.out", workdir / f"{token}.err"
    with open(log_out, "w") as out, open(log_err, "w") as err:
        proc = subprocess.Popen(_mpirun(args), stdout=out, stderr=err, env=clean_env(env),
                                start_new_session=True)
    ranks = _rank_pids(proc.pid, 2)
    deadline = time.monotonic() + timeout
    triggered = False
    while time.monotonic() < deadline and proc.poll() is None:
        if trigger in log_out.read_text():
            triggered = True
            break
        time.sleep(0.002)
    if triggered:
        for pid in ranks.values():
            os.kill(pid, signal.SIGSTOP)
        if action == "term-mpirun":
            os.kill(proc.pid, signal.SIGTERM)  # mpirun continues and terminates the ranks
        elif action == "term-ranks":
            for pid in ranks.values():
                os.kill(pid, signal.SIGTERM)
        elif action == "kill-rank1":
            os.kill(ranks[1], signal.SIGKILL)
        if action != "term-mpirun":  # mpirun continues its ranks itself to end them
            for pid in ranks.values():
                try:
                    os.kill(pid, signal.SIGCONT)
                except ProcessLookupError:
                    pass
    hung = _finish(proc, token, timeout)
    return {"returncode": proc.returncode, "stdout": log_out.read_text(),
            "stderr": log_err.read_text(), "hung": hung, "triggered": triggered,
            "leftovers": _leftovers(token), "ranks": ranks}


def read_result(path):
    """Root attributes and ``{index: (attrs, gap, pressure)}`` of the complete steps,
    read whole with h5py on rank 0 and handed to every rank (None if it does not open)."""
    def read():
        try:
            f = h5py.File(path, "r")
        except OSError as exc:
            return {"error": str(exc)}
        with f:
            steps, incomplete = {}, []
            for name in f:
                if not name.startswith("step_"):
                    continue
                group = f[name]
                attrs = read_attrs(group)
                if attrs.get("complete") is True:
                    steps[int(name[5:])] = (attrs, group["gap"][...], group["pressure"][...])
                else:
                    incomplete.append(name)
            return {"attrs": read_attrs(f), "steps": steps, "incomplete": incomplete,
                    "topography": f["topography"][...]}
    return wait_for_root(read)


SCALARS = ("mean_gap", "mean_pressure", "contact_fraction", "iterations", "converged",
           "reason", "elastic_energy", "kkt_pressure", "kkt_gap")


def assert_steps_equal(result, reference, indices):
    """Steps ``indices`` of ``result`` are complete, whole, and equal the reference's."""
    assert "error" not in result, result.get("error")
    assert sorted(result["steps"]) == sorted(indices), (sorted(result["steps"]), indices)
    for i in indices:
        attrs, gap, pressure = result["steps"][i]
        ref_attrs, ref_gap, ref_pressure = reference["steps"][i]
        assert gap.shape == SHAPE and pressure.shape == SHAPE
        assert np.all(np.isfinite(gap)) and np.all(np.isfinite(pressure))
        assert attrs["solution.converged"] is True
        # the same scene on the same ranks from the same state: the same arithmetic
        np.testing.assert_array_equal(gap, ref_gap)
        np.testing.assert_array_equal(pressure, ref_pressure)
        for key in SCALARS:
            assert attrs[f"solution.{key}"] == ref_attrs[f"solution.{key}"], (i, key)
    np.testing.assert_array_equal(result["topography"], reference["topography"])


def assert_prefix(result, at_least, reference):
    """The complete steps are 0..k-1 with at_least <= k < NSTEPS; returns k."""
    assert "error" not in result, result.get("error")
    k = len(result["steps"])
    assert sorted(result["steps"]) == list(range(k)), sorted(result["steps"])
    assert at_least <= k < NSTEPS, k
    assert result["attrs"]["complete"] is False
    assert_steps_equal(result, reference, range(k))
    return k


def assert_resumed(proc, result, reference, already):
    """A rerun of the same command continued the run and completed it."""
    assert not proc["hung"] and proc["returncode"] == 0, proc["stderr"][-3000:]
    assert "continuing an interrupted run" in proc["stdout"]
    assert proc["stdout"].count("complete in the file, not recomputed") == already
    assert proc["leftovers"] == []
    assert result["attrs"]["complete"] is True and result["attrs"]["resume_count"] >= 1
    assert result["incomplete"] == []
    assert_steps_equal(result, reference, range(NSTEPS))


# ----------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def shared():
    """A directory shared by all ranks for the whole module."""
    with shared_directory(COMM, prefix="petgap-faults-") as path:
        yield path


@pytest.fixture(scope="module")
def reference(shared):
    """The sweep run without interruption (2 ranks): what every interrupted run must match."""
    scene = shared / "reference.toml"
    out = shared / "reference.h5"
    if COMM.rank == 0:
        scene.write_text(SWEEP)
    COMM.Barrier()
    (proc,) = run_many([(_mpirun(["petgap", "run", scene, "-o", out, "-q"]), out)], timeout=120)
    assert proc["returncode"] == 0 and not proc["hung"], proc["stderr"][-3000:]
    result = read_result(out)
    assert result["attrs"]["complete"] is True and sorted(result["steps"]) == list(range(NSTEPS))
    result["path"] = out
    return result


def _case_dir(shared, name):
    path = shared / name
    if COMM.rank == 0:
        path.mkdir()
        (path / "sweep.toml").write_text(SWEEP)
    COMM.Barrier()
    return path


# -------------------------------------------------------------- bad input
def _bad_input_cases(d):
    """``(name, args, fragments that the one error line must contain)``; files made on rank 0."""
    def scene(name, text):
        path = d / f"{name}.toml"
        path.write_text(text)
        return path

    rng = np.random.default_rng(1)
    h = rng.standard_normal((32, 32))
    nan, inf = h.copy(), h.copy()
    nan[3, 5], inf[30, 7] = np.nan, -np.inf
    np.save(d / "nan.npy", nan)
    np.save(d / "inf.npy", inf)
    np.save(d / "huge.npy", np.full((32, 32), 1e300))
    np.save(d / "narrow.npy", h[:, :31])
    np.save(d / "cube.npy", h[None])
    many = (SMALL.replace("nx = 32", "nx = 32.5")
            .replace("seed = 3", 'seed = 3\nroughness = 2\nrms_height = -0.5')
            .replace('"8 a0"', '"8 nm"').replace("0.002, 0.004", '"0.002 MPa"')
            .replace("[solver]", "[solvr]"))
    cases = [
        ("malformed", SMALL.replace("nx = 32", "nx = = 32"), ["not valid TOML", "line 3"]),
        # every problem of a scene is reported at once, each naming its key
        ("many-errors", many, ["6 errors", "grid.nx = 32.5: not an integer",
                               "surface.roughness = 2: unknown key",
                               "surface.rms_height = -0.5: out of range",
                               'surface.lambda_min = "8 nm": not a length', '"32 a0"',
                               'control.values = ["0.002 MPa"]', "not a number",
                               "[solvr]: unknown section (did you mean [solver]?)"]),
        # found when the run is built, still before the result file is made
        ("unresolved-adhesion", SMALL.replace("[control]", '[interaction]\nkind = "exponential"\n'
                                              'work_of_adhesion = 0.05\nrange = "0.2 a0"\n'
                                              'resolution_check = "error"\n\n[control]'),
         ["interaction not resolved by the grid", "range rho = 0.2 is 0.2 pixels"]),
        ("negative-load", SMALL.replace("0.002, 0.004", "0.002, -0.004"),
         ["control.values", "item 1 (-0.004) is tensile", 'interaction.kind = "hard-wall"']),
        ("topography-nan", FILE_SCENE.format(path="nan.npy", extra=""),
         ["nan.npy", "non-finite", "(3, 5)"]),
        ("topography-inf", FILE_SCENE.format(path="inf.npy", extra=""),
         ["inf.npy", "non-finite", "(30, 7)"]),
        ("topography-huge", FILE_SCENE.format(path="huge.npy", extra=""),
         ["huge.npy", "heights up to 1e+300", "at most 1e+100"]),
        ("topography-shape", FILE_SCENE.format(path="narrow.npy", extra=""),
         ["narrow.npy", "shape (32, 31)", "grid is (32, 32)"]),
        ("topography-3d", FILE_SCENE.format(path="cube.npy", extra=""),
         ["cube.npy", "3D", "must be 2D"]),
        ("topography-missing", FILE_SCENE.format(path="absent.npy", extra=""),
         ["surface.path", "absent.npy", "no such file"]),
    ]
    jobs = [(name, ["petgap", "run", scene(name, text), "-o", d / f"{name}.h5"], fragments)
            for name, text, fragments in cases]
    jobs.append(("scene-missing", ["petgap", "run", d / "absent.toml", "-o", d / "x.h5"],
                 ["absent.toml", "not found"]))
    jobs.append(("output-dir-missing", ["petgap", "run", scene("valid-1", SMALL), "-o",
                                        d / "nowhere" / "r.h5"], ["nowhere", "does not exist"]))
    jobs.append(("output-is-dir", ["petgap", "run", scene("valid-2", SMALL), "-o", d],
                 [str(d), "is a directory"]))
    return jobs


def test_bad_input_is_one_clean_error(comm, shared):
    """Malformed TOML, unknown keys, wrong signs, units and types, NaN/inf or misshapen
    topographies, missing files and output directories: each is exit 2 with
    one ``petgap: error:`` line naming the key or file and the problem, no traceback,
    no result file, no process left -- on 2 ranks, so a rank-local error would hang."""
    d = shared / "bad"
    cases = wait_for_root(lambda: (d.mkdir(), _bad_input_cases(d))[1])
    outcomes = run_many([(_mpirun(args), args[2]) for _, args, _ in cases], timeout=60)
    problems = []
    for (name, args, fragments), proc in zip(cases, outcomes):
        err = proc["stderr"]
        missing = [f for f in fragments if f not in err]
        if proc["hung"] or proc["returncode"] != 2 or err.count("petgap: error:") != 1 \
                or "Traceback" in err or missing or proc["leftovers"]:
            problems.append(f"{name}: exit {proc['returncode']}, hung {proc['hung']}, "
                            f"missing {missing}, left {proc['leftovers']}:\n{err[-1500:]}")
        if name != "output-is-dir" and Path(args[4]).exists():
            problems.append(f"{name}: {args[4]} was created")
        out = Path(args[4])
        left = [p for p in (out.with_name(f".{out.name}.partial"),
                            out.with_name(f".{out.name}.lock")) if p.exists()]
        if left:
            problems.append(f"{name}: left {left}")
    assert not problems, "\n".join(problems)


def test_existing_output_is_never_overwritten(comm, shared, reference):
    """Without --overwrite an existing output is never replaced, and the outcome says why:
    this scene's finished result is a no-op that says so (exit 0, no banner); an
    interrupted result of another scene names the first differing key with both values;
    a truncated result, a file that is not HDF5 and an HDF5 file that is not a petgap
    result are each refused with that reason (exit 2, the path and --overwrite named).
    Every file is left byte-identical."""
    d = shared / "existing"

    def prepare():
        d.mkdir()
        scene = d / "sweep.toml"
        scene.write_text(SWEEP)
        shutil.copy(reference["path"], d / "finished.h5")
        shutil.copy(reference["path"], d / "other.h5")
        with h5py.File(d / "other.h5", "r+") as f:  # another scene's interrupted run
            f.attrs["scene"] = SWEEP.replace("seed = 3", "seed = 4")
            f.attrs["scene_resolved"] = f.attrs["scene_resolved"].replace('"seed":3',
                                                                          '"seed":4')
            f.attrs["complete"] = np.bool_(False)
        whole = Path(reference["path"]).read_bytes()
        (d / "truncated.h5").write_bytes(whole[:len(whole) // 3])
        (d / "foreign.h5").write_bytes(b"somebody else's data\n")
        with h5py.File(d / "alien.h5", "w") as f:
            f["data"] = np.zeros(3)
        return {name: (d / f"{name}.h5").read_bytes()
                for name in ("finished", "other", "truncated", "foreign", "alien")}
    before = wait_for_root(prepare)
    outcomes = run_many([(_mpirun(["petgap", "run", d / "sweep.toml", "-o", d / f"{name}.h5"]),
                          d / f"{name}.h5") for name in before], timeout=60)
    after = wait_for_root(lambda: {name: (d / f"{name}.h5").read_bytes() for name in before})
    why = {"other": f"different scene (surface.seed = 4 in the file, 3 in {d / 'sweep.toml'})",
           "truncated": "not a readable HDF5 file (truncated",
           "foreign": "not a readable HDF5 file",
           "alien": "not a petgap result"}
    for name, proc in zip(before, outcomes):
        assert not proc["hung"] and proc["leftovers"] == [], name
        assert after[name] == before[name], name
        assert "MPI_ABORT" not in proc["stderr"] and "Traceback" not in proc["stderr"]
        if name == "finished":
            assert proc["returncode"] == 0, proc["stderr"]
            assert f"{d / name}.h5 is complete" in proc["stdout"]
            assert "nothing to do" in proc["stdout"]
            assert "error" not in proc["stderr"] and "Primary job" not in proc["stderr"]
            assert "making the surface" not in proc["stdout"]
            continue
        assert proc["returncode"] == 2, (name, proc["stderr"])
        assert proc["stderr"].count("petgap: error:") == 1
        assert f"{d / name}.h5" in proc["stderr"] and "--overwrite" in proc["stderr"]
        assert why[name] in proc["stderr"], (name, proc["stderr"])


def test_output_that_can_never_be_a_result(comm, shared):
    """The scene file itself, the topography file, a device and a directory-like path
    (trailing slash, existing directory) are refused as outputs, --overwrite or not:
    exit 2, one error naming the path and why, before anything is made, nothing
    changed."""
    d = shared / "never"

    def prepare():
        d.mkdir()
        (d / "small.toml").write_text(SMALL)
        np.save(d / "heights.npy", np.random.default_rng(2).standard_normal((32, 32)))
        (d / "file.toml").write_text(FILE_SCENE.format(path="heights.npy", extra=""))
        (d / "link.h5").symlink_to(d / "small.toml")
        (d / "sub").mkdir()
        return {p.name: p.read_bytes() for p in (d / "small.toml", d / "heights.npy")}
    before = wait_for_root(prepare)
    small, file_scene = d / "small.toml", d / "file.toml"
    cases = [  # (scene, output, extra args, fragments of the message)
        (small, small, ["--overwrite"], [f"output path {small} is the scene file"]),
        (small, d / "link.h5", [], [f"output path {d / 'link.h5'} is the scene file"]),
        (file_scene, d / "heights.npy", ["--overwrite"],
         [f"output path {d / 'heights.npy'} is the topography file (surface.path)"]),
        (small, "/dev/null", [], ["/dev/null is not a regular file"]),
        (small, "/dev/null", ["--overwrite"], ["/dev/null is not a regular file"]),
        (small, f"{d / 'newdir'}/", ["--overwrite"], [f"{d / 'newdir'}/ names a directory"]),
        (small, d / "sub", [], [f"{d / 'sub'} is a directory"]),
    ]
    # each job's token (to find leftover processes) is its own copy of the scene: the
    # output path (/dev/null) may be in other processes' command lines; the two jobs that
    # write onto small.toml itself have it in their command lines both, so the one given
    # it through link.h5 is found by that name
    copies = wait_for_root(lambda: [
        shutil.copy(scene, d / f"job{i}-{scene.name}") if out not in (small, d / "link.h5")
        else scene for i, (scene, out, _, _) in enumerate(cases)])
    tokens = [d / "link.h5" if out == d / "link.h5" else copy
              for copy, (_, out, _, _) in zip(copies, cases)]
    jobs = [(_mpirun(["petgap", "run", copy, "-o", out] + extra), token)
            for copy, token, (_, out, extra, _) in zip(copies, tokens, cases)]
    # the jobs naming small.toml run one after the other: a job's token must not be in the
    # command line of another job still running when its leftovers are looked for
    outcomes = run_many(jobs[:1], timeout=60) + run_many(jobs[1:], timeout=60)
    after = wait_for_root(lambda: {name: (d / name).read_bytes() for name in before})
    assert after == before
    assert wait_for_root(lambda: not (d / "newdir").exists())
    for (scene, out, extra, fragments), proc in zip(cases, outcomes):
        err = proc["stderr"]
        assert not proc["hung"] and proc["returncode"] == 2, (out, extra, err)
        assert err.count("petgap: error:") == 1 and "Traceback" not in err, err
        assert all(f in err for f in fragments), (fragments, err)
        assert "making the surface" not in proc["stdout"]
        assert proc["leftovers"] == []


def test_unwritable_output_directory(comm, shared):
    """An output directory that cannot be written (a read-only file system here, since
    root ignores permissions) is exit 2 with a message naming the path, before any
    expensive work (no surface is made)."""
    d = shared / "readonly"

    def prepare():
        d.mkdir()
        (shared / "small.toml").write_text(SMALL)
        if os.geteuid() != 0:
            d.chmod(0o555)
            return None
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(d)],
                              capture_output=True, text=True)
        return None if done.returncode == 0 else done.stderr.strip()
    why = wait_for_root(prepare)
    if why is not None:
        pytest.skip(f"cannot make a read-only directory as root here (mount: {why})")
    try:
        (proc,) = run_many([(_mpirun(["petgap", "run", shared / "small.toml",
                                      "-o", d / "r.h5"]), d / "r.h5")])
    finally:
        wait_for_root(lambda: subprocess.run(["umount", str(d)], capture_output=True)
                      if os.geteuid() == 0 else d.chmod(0o755))
    assert not proc["hung"] and proc["returncode"] == 2, proc["stderr"]
    assert proc["stderr"].count("petgap: error:") == 1 and "Traceback" not in proc["stderr"]
    assert f"{d / 'r.h5'}" in proc["stderr"] and "not writable" in proc["stderr"]
    assert "making the surface" not in proc["stdout"]
    assert proc["leftovers"] == []


# ------------------------------------------------------- interrupted sweeps
INTERRUPTIONS = {
    # action: (trigger line in the progress log, steps certainly complete by then)
    "term-mpirun": ("step 5 (adhesive,", 5),
    "term-ranks": ("step 2 (reference,", 2),
    "kill-rank1": ("step 4 converged", 4),
}


@pytest.mark.parametrize("action", list(INTERRUPTIONS))
def test_interrupted_sweep_keeps_finished_steps_and_resumes(comm, shared, reference, action):
    """SIGTERM to mpirun (as a user's Ctrl-C or a batch system), SIGTERM to every rank,
    or SIGKILL of one rank, in the middle of the sweep: the job ends (non-zero, no
    process left, the signal named when a rank died of it); the steps marked complete
    are exactly those finished before, read back whole and equal the uninterrupted
    run's; the same command then continues from the first unfinished step and ends
    with the uninterrupted run's results."""
    trigger, finished = INTERRUPTIONS[action]
    d = _case_dir(shared, action)
    out = d / "sweep.h5"
    args = ["petgap", "run", d / "sweep.toml", "-o", out]
    # Open MPI's mpirun lets its ranks run on for odls_base_sigkill_timeout = 1 s after a
    # SIGTERM (time enough to finish this small sweep); 0 keeps the signal where the ranks
    # were stopped.  SIGTERM to the ranks themselves acts at once.
    env = {"OMPI_MCA_odls_base_sigkill_timeout": "0"} if action == "term-mpirun" else None
    proc = wait_for_root(lambda: interrupt(args, d, trigger, action, token=out, env=env))
    assert proc["triggered"], proc["stdout"][-2000:] + proc["stderr"][-2000:]
    assert not proc["hung"] and proc["returncode"] != 0, proc["stderr"][-2000:]
    assert proc["leftovers"] == []
    if action == "kill-rank1":
        assert "rank 1" in proc["stderr"] and "signal 9" in proc["stderr"]
    elif action == "term-ranks":
        assert "signal 15" in proc["stderr"]
    # the ranks were stopped within milliseconds of the trigger: at most one more step
    k = assert_prefix(read_result(out), finished, reference)
    assert k <= finished + 1

    (again,) = run_many([(_mpirun(args), out)], timeout=120)
    assert_resumed(again, read_result(out), reference, already=k)


# ---------------------------------------------------------------- full disk
def _tmpfs(d, size):
    """Mount a tmpfs of ``size`` on ``d`` (rank 0); None, or why it cannot be done."""
    if os.geteuid() != 0:
        return "not root"
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(d)],
                          capture_output=True, text=True)
    return None if done.returncode == 0 else f"mount: {done.stderr.strip()}"


def _grow(d):
    subprocess.run(["mount", "-o", "remount,size=16m", str(d)], check=True, capture_output=True)


# The wrapper turns the free-space check off, so that HDF5 itself runs out of space.
NO_CHECK = ("import sys; import petgap.io.results as h; h.FREE_SPACE_MARGIN = -2 ** 62; "
            "import petgap.app.main as c; sys.exit(c.main(sys.argv[1:]))")


@pytest.mark.parametrize("where", ["before-write", "inside-hdf5"])
def test_full_disk_keeps_finished_steps_and_resumes(comm, shared, reference, where):
    """The sweep on a small tmpfs that fills up.  before-write: petgap's free-space
    check refuses the next step (exit 2, "not enough free space", the file and the
    numbers named).  inside-hdf5: with the check off, HDF5's own write fails: the job
    must still end (no hang in closing the file), name the failed write, and leave
    the file openable -- not "truncated" -- with its finished steps.  Both: the
    steps marked complete equal the uninterrupted run's, and after making room the
    same command completes the run with the same results."""
    d = _case_dir(shared, where)
    disk = d / "disk"
    size = FREE_SPACE_MARGIN + 300 * 1024 if where == "before-write" else 300 * 1024
    why = wait_for_root(lambda: (disk.mkdir(), _tmpfs(disk, size))[1])
    if why is not None:
        pytest.skip(f"no small file system to fill: {why}")
    out = disk / "sweep.h5"
    args = ["petgap", "run", d / "sweep.toml", "-o", out]
    if where == "inside-hdf5":
        args = [sys.executable, "-c", NO_CHECK] + args[1:]
    try:
        (proc,) = run_many([(_mpirun(args), out)], timeout=90)
        full = read_result(out)
        wait_for_root(lambda: _grow(disk))
        (again,) = run_many([(_mpirun(args), out)], timeout=120)
        final = read_result(out)
    finally:
        wait_for_root(lambda: subprocess.run(["umount", str(disk)], capture_output=True))
    assert not proc["hung"] and proc["returncode"] != 0, proc["stderr"][-2000:]
    assert proc["leftovers"] == []
    assert proc["stderr"].count("petgap: error:") == 1, proc["stderr"][-2000:]
    if where == "before-write":
        assert proc["returncode"] == 2 and "Traceback" not in proc["stderr"]
        assert f"not enough free space to write to {out}" in proc["stderr"]
        assert "bytes free" in proc["stderr"] and "rerun the same command" in proc["stderr"]
    else:
        assert f"writing {out} failed" in proc["stderr"]
    k = assert_prefix(full, 1, reference)
    assert_resumed(again, final, reference, already=k)


def test_resume_refuses_a_changed_topography_file(comm, shared):
    """An interrupted run from a topography file is continued only while that file is
    what its finished steps were made from (the SHA-256 stored at creation): after the
    file changed, the same command refuses, naming the file, and leaves the result."""
    d = shared / "changed"

    def prepare():
        d.mkdir()
        np.save(d / "heights.npy", np.random.default_rng(5).standard_normal((32, 32)))
        (d / "file.toml").write_text(FILE_SCENE.format(path="heights.npy", extra=""))
    wait_for_root(prepare)
    args = _mpirun(["petgap", "run", d / "file.toml", "-o", d / "r.h5"])
    (proc,) = run_many([(args, d / "r.h5")])
    assert proc["returncode"] == 0, proc["stderr"]

    def interrupted():
        with h5py.File(d / "r.h5", "r+") as f:  # as if killed before the last step
            f.attrs["complete"] = np.bool_(False)
            del f["step_0000"]
            stored = f.attrs["surface_sha256"]
        return stored, (d / "r.h5").read_bytes()
    stored, before = wait_for_root(interrupted)
    assert len(stored) == 64
    same, = run_many([(args, d / "r.h5")])  # unchanged file: continued
    assert same["returncode"] == 0 and "continuing an interrupted run" in same["stdout"]

    def change():
        (d / "r.h5").write_bytes(before)
        h = np.load(d / "heights.npy")
        h[0, 0] += 1
        np.save(d / "heights.npy", h)
    wait_for_root(change)
    proc, = run_many([(args, d / "r.h5")])
    err = proc["stderr"]
    assert proc["returncode"] == 2 and err.count("petgap: error:") == 1, err
    assert f"topography file {d / 'heights.npy'} (surface.path) changed" in err
    assert "--overwrite" in err and "making the surface" not in proc["stdout"]
    assert wait_for_root(lambda: (d / "r.h5").read_bytes()) == before


# ------------------------------------------------------------- one writer
HOLD_LOCK = ("import fcntl, os, sys, time; fd = os.open(sys.argv[1], os.O_RDWR | os.O_CREAT); "
             "fcntl.flock(fd, fcntl.LOCK_EX); os.write(fd, b'host test, pid %d' % os.getpid()); "
             "print('locked', flush=True); time.sleep(120)")


def test_one_writer_per_result_file(comm, shared):
    """While another job holds the result's lock, a run refuses at once (exit 2, on every
    rank, naming the holder) and touches nothing; once the holder is gone -- killed, as a
    crashed job would be -- the same command runs: a dead job leaves no stuck lock."""
    d = shared / "locked"
    wait_for_root(lambda: (d.mkdir(), (d / "small.toml").write_text(SMALL)))
    out = d / "r.h5"
    args = _mpirun(["petgap", "run", d / "small.toml", "-o", out])

    def while_held():
        holder = subprocess.Popen([sys.executable, "-c", HOLD_LOCK, str(d / ".r.h5.lock")],
                                  stdout=subprocess.PIPE, text=True)
        try:
            assert holder.stdout.readline().strip() == "locked"
            proc = subprocess.run(args, capture_output=True, text=True, env=clean_env(),
                                  timeout=60)
        finally:
            holder.kill()           # as a crashed job: no unlock, no clean-up
            holder.wait()
        return {"returncode": proc.returncode, "stderr": proc.stderr}
    refused = wait_for_root(while_held)
    err = refused["stderr"]
    assert refused["returncode"] == 2 and err.count("petgap: error:") == 1, err
    assert f"another petgap job is writing {out}" in err and "host test, pid" in err
    assert not wait_for_root(out.exists)
    (ran,) = run_many([(args, out)])
    assert ran["returncode"] == 0, ran["stderr"]
    assert wait_for_root(lambda: not (d / ".r.h5.lock").exists())   # released and removed


def test_file_of_a_job_killed_while_creating_it_is_started_again(comm, shared):
    """A new result is made as ``.<name>.partial`` and renamed when its provenance and
    topography are in: a job killed while creating it leaves no unreadable file at the
    output, and the same command recognises the unfinished file, says so and starts again."""
    d = shared / "creation"

    def prepare():
        d.mkdir()
        (d / "small.toml").write_text(SMALL)
        (d / ".r.h5.partial").write_bytes(b"\x89HDF\r\n\x1a\n" + b"\0" * 100)   # truncated
        (d / ".r.h5.lock").write_text("host gone, pid 1")       # a dead job's sidecar
    wait_for_root(prepare)
    out = d / "r.h5"
    (proc,) = run_many([(_mpirun(["petgap", "run", d / "small.toml", "-o", out]), out)])
    assert proc["returncode"] == 0, proc["stderr"]
    assert f"{d / '.r.h5.partial'} is the unfinished file of a petgap run killed while " \
           f"creating {out}; starting again" in proc["stdout"] + proc["stderr"]
    result = read_result(out)
    assert "error" not in result and result["attrs"]["complete"] is True
    assert sorted(result["steps"]) == [0, 1] and result["incomplete"] == []
    assert not wait_for_root((d / ".r.h5.partial").exists)


# ------------------------------------------- instrument files, geometry, check = run
def wsxm(columns=16, rows=16, width="160 nm", cut_header=None, cut_data=None):
    """A small WSxM ``.top`` file (float64 heights), whole or cut at a byte of its header
    or of its data."""
    body = "\r\n".join([
        "[Control]", f"    X Amplitude: {width}", "    Y Amplitude: 160 nm",
        "[General Info]", "    Acquisition time: 03/11/2011, 20:23:46.484",
        "    Image Data Type: double", f"    Number of columns: {columns}",
        f"    Number of rows: {rows}", "    Z Amplitude: 2 nm",
        "[Miscellaneous]", "    Maximum: 1", "    Minimum: -1", "", "[Header end]", ""])
    start = "WSxM file copyright Nanotec Electronica\r\nSxM Image file\r\n"
    size = len(start) + len("Image header size: 0000\r\n") + len(body)
    header = f"{start}Image header size: {size:04d}\r\n{body}".encode("latin-1")
    data = np.random.default_rng(4).uniform(-1, 1, (rows, columns)).astype("<f8").tobytes()
    if cut_header is not None:
        return header[:cut_header]
    return header + data[:cut_data]


def text_map(width):
    """A 16 x 16 text map whose header gives ``width``."""
    rows = np.random.default_rng(5).standard_normal((16, 16))
    return (f"# Width: {width}\n# Height: 1 m\n# Value units: m\n"
            + "\n".join(" ".join(f"{v:.6g}" for v in row) for row in rows) + "\n")


#: name: (file written, its bytes or a writer, extra surface keys, fragments of the error);
#: every error must also lead with the file (after the scene's name, and the key of a
#: unit petgap cannot convert).
INSTRUMENT_FILES = {
    "cut-header": ("cut.top", wsxm(cut_header=200), "",
                   ["cut inside its header", "no [Header end] line"]),
    "zero-size-top": ("zero.top", wsxm(width="0 nm"), "", ["physical size 0 x 160 nm"]),
    "zero-width-text": ("zero.txt", text_map("0 m").encode(), "", ["physical size 0 x 1 m"]),
    "empty-text": ("empty.txt", b"", "", ["is empty (0 bytes)"]),
    "truncated-top": ("truncated.top", wsxm(cut_data=1001), "",
                      ["is truncated", "16 x 16 heights (2048 bytes)", "holds 1001 bytes"]),
    "negative-width": ("negative.txt", text_map("-1 m").encode(), "",
                       ["physical size -1 x 1 m", "allowed: a size > 0"]),
    "not-igor": ("random.ibw", np.random.default_rng(6).bytes(800), "",
                 ["extension .ibw says Igor binary wave", "not recognise its format"]),
    "one-line": ("line.npy", lambda p: np.save(p, np.ones((64, 1))), "",
                 ["64 x 1 points", "line scan", "at least 2 points along x and along y"]),
    "all-undefined": ("nan.npy", lambda p: np.save(p, np.full((16, 16), np.nan)),
                      'undefined = "harmonic"\n', ["every point is undefined", "256"]),
    "empty-npy": ("empty.npy", b"", "", ["is empty (0 bytes)"]),
    "flat": ("flat.npy", lambda p: np.save(p, np.full((16, 16), 2.5)), "", ["is flat"]),
    "unknown-unit": ("good.top", wsxm(), "", ["units.length", "'furlong'", "'nm'"]),
}

#: A file scene that takes its grid from the file.
MEASURED_SCENE = FILE_SCENE.replace("\n[grid]\nnx = 32\n", "")


def _instrument_cases(d, commands=("check", "run")):
    """Write the files of :data:`INSTRUMENT_FILES` and a scene of each per command (each
    job's own, so that its command line names it alone), on rank 0; the scenes' paths."""
    scenes = {}
    for name, (file, content, extra, _) in INSTRUMENT_FILES.items():
        if callable(content):
            content(d / file)
        else:
            (d / file).write_bytes(content)
        if name == "unknown-unit":
            extra += '\n[units]\nlength = "furlong"\n'
        for command in commands:
            scenes[name, command] = d / f"{name}-{command}.toml"
            scenes[name, command].write_text(MEASURED_SCENE.format(path=file, extra=extra))
    return scenes


def _refused(proc, scene, fragments, leading=None):
    """The problems of a job that should have ended in one clean error (an empty list)."""
    err = proc["stderr"]
    problems = []
    if proc["hung"] or proc["returncode"] != 2 or err.count("petgap: error:") != 1 \
            or "Traceback" in err or proc["leftovers"]:
        problems.append(f"exit {proc['returncode']}, hung {proc['hung']}, "
                        f"left {proc['leftovers']}")
    problems += [f"missing {f!r}" for f in fragments if f not in err]
    line = err.split("petgap: error: ", 1)[-1].removeprefix(f"{scene}: ")
    line = re.sub(r"^[a-z_.]+ = '[^']*': ", "", line)   # the key a unit error names first
    if leading is not None and not line.startswith((f"topography {leading}",
                                                    f"topography file {leading}")):
        problems.append(f"does not lead with the file {leading}")
    if "is missing" in line:
        problems.append("framed as a missing key")
    return [f"{p}:\n{err[-1500:]}" for p in problems]


def test_bad_instrument_files_are_refused_naming_the_file(comm, shared):
    """Cut, truncated, empty and mislabelled instrument files, zero and negative sizes, a
    line scan, a map without a defined point, a flat map, a unit SurfaceTopography cannot
    convert:
    ``petgap check`` and ``petgap run`` each end within seconds -- no reader may loop --
    in one error on every rank that leads with the file and says what is wrong with it
    (naming units.length for the unit), and make no result."""
    d = shared / "instrument"
    scenes = wait_for_root(lambda: (d.mkdir(), _instrument_cases(d))[1])
    jobs = [(_mpirun(["petgap", command, scene] + (["-o", d / f"{name}.h5"]
                                                   if command == "run" else [])), scene)
            for (name, command), scene in scenes.items()]
    # the readers' own time limit is a minute: a job still running at 45 s hangs
    outcomes = run_many(jobs, timeout=45)
    problems = []
    for ((name, command), scene), proc in zip(scenes.items(), outcomes):
        file, _, _, fragments = INSTRUMENT_FILES[name]
        problems += [f"{name} ({command}): {p}" for p in
                     _refused(proc, scene, fragments, d / file)]
    made = wait_for_root(lambda: sorted(p.name for p in d.glob("*.h5")))
    assert not problems and made == [], "\n".join(problems) + f"\nmade: {made}"


def test_a_line_scan_is_refused_alike_on_any_number_of_ranks(comm, shared):
    """A 64 x 1 map is refused as a line scan, in the same words on one rank and on two
    (not as a decomposition that fewer ranks would fix)."""
    d = shared / "line-ranks"
    scenes = wait_for_root(lambda: (d.mkdir(), _instrument_cases(d, ("run",)))[1])
    scene = scenes["one-line", "run"]
    outcomes = run_many([(_mpirun(["petgap", "run", scene, "-o", d / f"{n}.h5"], ranks=n),
                          d / f"{n}.h5") for n in (1, 2)])
    one, two = (o["stderr"].split("petgap: error: ", 1)[-1].splitlines()[0] for o in outcomes)
    for proc in outcomes:
        assert not _refused(proc, scene, ["line scan"], d / "line.npy"), proc["stderr"]
    assert one == two and "cannot be split" not in one and "fewer ranks" not in one


INDENTER_SCENE = SMALL.replace('hurst = 0.8\nlambda_min = "8 a0"\nseed = 3',
                              'kind = "{kind}"\nradius = 1e-300')


def test_unresolved_indenters_and_check_agrees_with_run(comm, shared):
    """A paraboloid and a sphere of radius 1e-300 (heights of 1e303, or a flat surface) are
    refused by ``check`` and ``run`` alike, naming surface.radius; ``check`` refuses
    whatever ``run`` refuses before it solves (here also the line scan and the map without
    a defined point) and, for a valid scene, prints the estimated memory per rank."""
    d = shared / "geometry"

    def prepare():
        d.mkdir()
        scenes = {(kind, command): d / f"{kind}-{command}.toml"
                  for kind in ("paraboloid", "sphere") for command in ("check", "run")}
        for (kind, _), scene in scenes.items():
            scene.write_text(INDENTER_SCENE.format(kind=kind))
        (d / "valid.toml").write_text(SMALL)
        return scenes
    scenes = wait_for_root(prepare)
    jobs = [(_mpirun(["petgap", command, scene] + (["-o", d / f"{kind}.h5"]
                                                   if command == "run" else [])), scene)
            for (kind, command), scene in scenes.items()]
    jobs.append((_mpirun(["petgap", "check", d / "valid.toml"]), d / "valid.toml"))
    *outcomes, valid = run_many(jobs, timeout=60)
    problems = []
    for ((kind, command), scene), proc in zip(scenes.items(), outcomes):
        problems += [f"{kind} ({command}): {p}" for p in _refused(
            proc, scene, ["surface.radius = 1e-300", f"the {kind} is not resolved",
                          "radius >= 1"])]
    assert not problems, "\n".join(problems)
    assert valid["returncode"] == 0, valid["stderr"]
    assert "# memory: about" in valid["stdout"] and "per rank at its peak on 2 ranks" \
        in valid["stdout"] and "(2 steps planned)" in valid["stdout"]


def test_scene_with_a_byte_order_mark_runs(comm, shared):
    """A scene file saved with a UTF-8 byte-order mark (as some Windows editors do) is
    read as the same scene without it."""
    d = shared / "bom"

    def prepare():
        d.mkdir()
        (d / "bom.toml").write_bytes(b"\xef\xbb\xbf" + SMALL.encode())
    wait_for_root(prepare)
    check, run = run_many([(_mpirun(["petgap", "check", d / "bom.toml"]), d / "bom.toml"),
                           (_mpirun(["petgap", "run", d / "bom.toml", "-o", d / "bom.h5",
                                     "-q"]), d / "bom.h5")])
    assert check["returncode"] == 0 and "bom.toml: valid" in check["stdout"], check["stderr"]
    assert run["returncode"] == 0, run["stderr"]
    assert read_result(d / "bom.h5")["attrs"]["complete"] is True


def test_output_links_and_sidecar_directories_are_refused(comm, shared):
    """A dangling symbolic link as --output, and a lock or .partial path that is a
    directory, are each refused naming the path and what it is, before anything is
    made; the link, its missing target and the directories are left as they were."""
    d = shared / "sidecars"

    def prepare():
        d.mkdir()
        (d / "small.toml").write_text(SMALL)
        (d / "dangling.h5").symlink_to(d / "gone" / "r.h5")
        (d / ".locked.h5.lock").mkdir()
        (d / ".partial.h5.partial").mkdir()
    wait_for_root(prepare)
    cases = [("dangling.h5", [f"output path {d / 'dangling.h5'} is a symbolic link to "
                              f"{d / 'gone' / 'r.h5'}, which does not exist"]),
             ("locked.h5", [f"{d / '.locked.h5.lock'} is a directory",
                            f"keeps the lock of {d / 'locked.h5'}"]),
             ("partial.h5", [f"{d / '.partial.h5.partial'} is a directory",
                             f"makes {d / 'partial.h5'} before renaming it"])]
    outcomes = run_many([(_mpirun(["petgap", "run", d / "small.toml", "-o", d / out]),
                          d / out) for out, _ in cases])
    problems = []
    for (out, fragments), proc in zip(cases, outcomes):
        problems += [f"{out}: {p}" for p in _refused(proc, d / "small.toml", fragments)]
        if "making the surface" in proc["stdout"]:
            problems.append(f"{out}: the surface was made")
    assert not problems, "\n".join(problems)

    def after():
        return ((d / "dangling.h5").is_symlink(), (d / "gone").exists(),
                (d / ".locked.h5.lock").is_dir(), (d / ".partial.h5.partial").is_dir(),
                sorted(p.name for p in d.iterdir() if p.is_file() and not p.is_symlink()))
    assert wait_for_root(after) == (True, False, True, True, ["small.toml"])


def test_post_names_a_truncated_result(comm, shared):
    """``petgap-post`` on a result file cut short names the file and says it is truncated,
    with the bytes it has and those its HDF5 superblock states."""
    d = shared / "post-truncated"

    def prepare():
        d.mkdir()
        with h5py.File(d / "whole.h5", "w") as f:
            f.attrs["petgap_version"] = "0"
            f["step_0000/gap"] = np.zeros((64, 64))
        whole = (d / "whole.h5").read_bytes()
        (d / "cut.h5").write_bytes(whole[:len(whole) // 2])
        return len(whole)
    size = wait_for_root(prepare)
    (proc,) = run_many([(_mpirun(["petgap-post", d / "cut.h5", "-o", d / "out"]),
                         d / "cut.h5")])
    err = proc["stderr"]
    assert not proc["hung"] and proc["returncode"] == 2 and "Traceback" not in err, err
    assert err.count("petgap-post: error:") == 1
    assert f"{d / 'cut.h5'}: truncated: {size // 2} bytes of the {size}" in err, err
