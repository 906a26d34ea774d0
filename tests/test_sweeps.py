"""The sweep runner (``benchmarks.sweep``) on a real cluster: a ``dask scheduler`` and two
``dask worker`` processes on 127.0.0.1, started here as separate processes. A sweep of tiny
runs (the hanging sheet at resolution 5-6, 2-3 frames) gives the same results as the same runs
in this process, also when one worker is killed in the middle of a run; the cache resumes a
stopped sweep and reruns only what a changed setting changes; a run that raises is reported
and the sweep goes on. The workers load their kernels once (from Taichi's offline cache),
then each run takes a fraction of a second.
"""
import os
import re
import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from benchmarks import sweep as sw
from benchmarks.harness import scene_run

# The tests on the cluster share one xdist worker, so the module's cluster starts once; they
# run sweeps (about 10-20 s with the cluster's start), hence slow.
def on_cluster(test):
    return pytest.mark.slow(pytest.mark.xdist_group("sweeps_cluster")(test))
ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DASK = os.path.join(os.path.dirname(sys.executable), "dask")
FRAMES = 3


def sheet(resolution):
    """The runs' settings: the free sheet (no strain solve), so that a worker loads few
    kernels; what is tested is where runs go and what comes back."""
    return {"cloth": {"resolution": resolution}, "strain": {"method": "none"}}


def probe(resolution, frames, claim_dir=None, hold=0.0, copy=0):
    """A run the workers import from here: ``harness.scene_run`` of the hanging sheet, with
    the worker's pid. The first run to start (``claim_dir``: it claims the folder's one file)
    writes its pid there and waits ``hold`` s before running, so the test can kill its worker
    in the middle of it; no other run waits. ``copy``: tells apart runs that are otherwise the
    same (runs with the same arguments are one task)."""
    if claim_dir is not None:
        try:
            fd = os.open(os.path.join(claim_dir, "claim"), os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:
            pass
        else:
            os.write(fd, str(os.getpid()).encode())
            os.close(fd)
            time.sleep(hold)
    out = scene_run("hanging", sheet(resolution), frames)
    out["pid"] = os.getpid()
    return out


def runs_of(resolutions, frames=FRAMES, **kw):
    return [sw.Run("tests.test_sweeps:probe", [r, frames, *kw.get("extra", [])],
                   f"hanging {r} x {frames}", scene=("hanging", sheet(r)))
            for r in resolutions]


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_for(what, timeout, step=0.1):
    t0 = time.time()
    while time.time() - t0 < timeout:
        value = what()
        if value:
            return value
        time.sleep(step)
    raise TimeoutError(f"waited {timeout} s")


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """A scheduler and two workers (one thread, one process each, no nanny: a killed worker
    stays dead), as separate processes; yields (address, the workers' Popen objects)."""
    from distributed import Client
    logs = tmp_path_factory.mktemp("dask_logs")
    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    procs = []

    def start(name, args):
        log = open(logs / f"{name}.log", "w")
        procs.append(subprocess.Popen([DASK, *args], cwd=ROOT, env=env, stdout=log,
                                      stderr=subprocess.STDOUT))
        return procs[-1]

    start("scheduler", ["scheduler", "--host", "127.0.0.1", "--port", str(port),
                        "--no-dashboard"])
    workers = [start(f"worker{i}", ["worker", address, "--nthreads", "1", "--nworkers", "1",
                                    "--no-nanny", "--no-dashboard", "--host", "127.0.0.1",
                                    "--name", f"w{i}", "--local-directory", str(logs)])
               for i in range(2)]
    try:
        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=60)
        yield address, workers
    finally:
        for p in reversed(procs):
            if p.poll() is None:
                p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()


@pytest.fixture(scope="module")
def local():
    """The same runs in this process: what every way of running must give."""
    return {r: scene_run("hanging", sheet(r), FRAMES) for r in (5, 6)}


def same(result, reference):
    np.testing.assert_array_equal(np.asarray(result["x"]), np.asarray(reference["x"]))
    np.testing.assert_array_equal(result["ke"], reference["ke"])


@on_cluster
@pytest.mark.no_jitter
def test_a_killed_worker_loses_only_its_task(cluster, local, tmp_path):
    """Six runs on two workers; the worker that starts the first run is killed (SIGKILL) while
    in it: that run is done again by the other worker, every result is the same as in this
    process, and the page-facing results carry no error."""
    from distributed import Client
    address, workers = cluster
    claim = tmp_path / "claim_dir"
    claim.mkdir()
    runs = [sw.Run("tests.test_sweeps:probe", [r, FRAMES, str(claim), 30.0, k],
                   f"hanging {r} #{k}", scene=("hanging", sheet(r)))
            for k in range(3) for r in (5, 6)]
    killed = {}

    def kill_when_claimed():
        path = claim / "claim"
        pid = wait_for(lambda: path.exists() and path.read_text(), 60)
        os.kill(int(pid), signal.SIGKILL)
        killed["pid"] = int(pid)

    import threading
    killer = threading.Thread(target=kill_when_claimed, daemon=True)
    killer.start()
    with Client(address) as client:
        results = sw.run_sweep(runs, str(tmp_path / "cache"), client=client)
    killer.join(5)
    assert "pid" in killed
    assert killed["pid"] in [w.pid for w in workers]
    assert [w.poll() is not None for w in workers].count(True) == 1     # one worker is gone
    for run, res in zip(runs, results):
        assert "error" not in res, res["error"]
        assert res["pid"] != killed["pid"]
        same(res, local[run.args[0]])


@on_cluster
@pytest.mark.no_jitter
def test_cache_resumes_and_reruns_only_what_changed(cluster, local, tmp_path):
    """A sweep stopped after two of four runs resumes with the other two; run again, nothing
    runs (not even a connection: the scheduler's address is a dead one); a changed setting
    reruns that run only; a run that raises is reported and not cached, the others go on."""
    address, _ = cluster
    folder = str(tmp_path / "cache")
    first = sw.run_sweep(runs_of([5, 6]), folder, scheduler=address)
    assert len(os.listdir(folder)) == 2
    lines = []

    class Stream:
        def write(self, s):
            lines.append(s)

        def flush(self):
            pass

    four = runs_of([5, 6, 7, 8])
    resumed = sw.run_sweep(four, folder, scheduler=address, stream=Stream())
    assert resumed[:2] == first
    assert len(os.listdir(folder)) == 4
    text = "".join(lines)
    assert "0 of 4 done" not in text and "2 of 4 done (2 cached), 0 failed, 2 left" in text
    assert re.search(r"4 of 4 done \(2 cached\), 0 failed, 0 left", text)
    same(resumed[0], local[5])
    same(resumed[1], local[6])

    # Everything cached: no cluster is needed at all.
    again = sw.run_sweep(runs_of([5, 6, 7, 8]), folder, scheduler="tcp://127.0.0.1:9")
    assert again == resumed

    # One changed setting (resolution 8 -> 4, and frames 3 -> 2 for resolution 7's run).
    changed = runs_of([5, 6]) + runs_of([7], frames=2) + runs_of([4])
    out = sw.run_sweep(changed, folder, scheduler=address)
    assert out[:2] == resumed[:2]
    assert out[2] != resumed[2] and len(out[2]["ke"]) == 2
    assert len(os.listdir(folder)) == 6

    # A run that raises (a resolution that is not a number): its error is reported, not cached.
    bad = sw.Run("tests.test_sweeps:probe", ["x", FRAMES], "hanging x x 3")
    out = sw.run_sweep(runs_of([5]) + [bad], folder, scheduler=address)
    assert out[0] == resumed[0] and "error" in out[1] and "Traceback" in out[1]["error"]
    assert len(os.listdir(folder)) == 6
    assert sw.failed_lines([None, bad], out)[1].startswith("Failed runs (1 of 2")


def test_cache_key_follows_what_decides_a_run():
    run = runs_of([5])[0]
    key = sw.run_key(run, "code A")
    assert sw.run_key(runs_of([5])[0], "code A") == key
    assert sw.run_key(run, "code B") != key                     # the code
    assert sw.run_key(runs_of([5], frames=2)[0], "code A") != key     # the arguments
    moved = runs_of([5])[0]
    moved.scene = ("hanging", {"cloth": {"resolution": 5}, "sim": {"gravity": [0.0, -9.0, 0.0]}})
    assert sw.run_key(moved, "code A") != key                   # the resolved configuration
    assert len(sw.code_fingerprint()) == 64


def echo_pid(value):
    """A run for ``in_own_process``: its argument back, with the process it ran in."""
    return {"value": value, "pid": os.getpid()}


def test_a_run_in_its_own_process_returns_its_result():
    """``Run(own_process=True)`` (an f32 stability case): the run goes to a new Python process
    and its JSON comes back; a run that fails there raises with the child's error."""
    out = sw.in_own_process("tests.test_sweeps:echo_pid", [[1.5, "a"]])
    assert out["value"] == [1.5, "a"] and out["pid"] != os.getpid()
    with pytest.raises(RuntimeError, match="TypeError"):
        sw.in_own_process("tests.test_sweeps:echo_pid", [1, 2])


def test_no_hand_made_pool_left_in_benchmarks():
    """Every benchmark that runs more than one configuration goes through the runner."""
    bench = os.path.join(ROOT, "benchmarks")
    for name in sorted(os.listdir(bench)):
        if name.endswith(".py"):
            text = open(os.path.join(bench, name)).read()
            for pool in ("ThreadPoolExecutor", "ProcessPoolExecutor", "multiprocessing.Pool",
                         "from multiprocessing import Pool", "cached_run("):
                assert pool not in text, f"benchmarks/{name} uses {pool}"
