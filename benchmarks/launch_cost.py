"""What a GPU run would pay per kernel launch, and how many launches a frame needs
(docs/speed/gpu_plan.md).

Three measurements on this machine's CPU back end:

1. **The cost of one launch**, with almost no work in it: a kernel without arguments, with
   one ndarray, with the dynamics step's arguments (four argpacks and the coefficient array,
   built by ``ImplicitEuler`` for a ``--n`` x ``--n`` sheet), each launched from Python, both
   Taichi's own way and replayed (``cloth/launch.py``, Loom's default); and the same
   one-ndarray kernel dispatched from a Taichi compute graph (``ti.graph``: the launches are
   recorded once and replayed without Python). The host-side cost does not depend on the
   device, so it is what each launch of a parallel design would cost on top of its work on a
   GPU too (plus the driver's own launch).
2. **A hanging frame's counts** at each ``--res``: Python launches a frame, the dynamics' CG
   iterations, the strain solve's AL rounds, Newton steps and PCG iterations, the multigrid's
   levels, the bytes of the arrays the solves stream, and ms a frame by stage: what a
   parallel design's launch count and memory traffic follow from.
3. **What the replayed launches save a frame** (``--replay``, scenes and resolutions as
   ``SCENE:RES``): two simulators of the scene, one launching Taichi's own way and one
   replaying, stepped in alternating blocks of frames from the same state (they stay
   identical, bit for bit), the median ms a frame of each.

    python -m benchmarks.launch_cost --res 46 91 181 --out docs/speed
    python -m benchmarks.launch_cost --res --replay hanging:9 hanging:25 hanging:46 drape:25 tshirt:0
"""
import argparse
import json
import os
import platform
import statistics
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)


def _timed(call, repeats):
    """Microseconds a call, the median of five batches of ``repeats`` (after a warm-up)."""
    import taichi as ti
    for _ in range(20):
        call()
    ti.sync()
    batches = []
    for _ in range(5):
        t = time.perf_counter()
        for _ in range(repeats):
            call()
        ti.sync()
        batches.append(1e6 * (time.perf_counter() - t) / repeats)
    return statistics.median(batches)


def launch_costs(n, repeats=400):
    """Microseconds a launch: {what: us}."""
    import taichi as ti
    from cloth import dynamics as D
    from cloth.model import ClothModel, Material, MeshArrays
    from cloth.sheet import make_sheet

    @ti.kernel
    def no_arguments():
        pass

    @ti.kernel
    def one_array(a: D.A):
        a[0] = 1.0

    @ti.kernel
    def one_loop(a: D.A):
        for i in range(a.shape[0]):
            a[i] += 1.0

    @ti.kernel
    def step_arguments(coef: D.A, mesh: D.MeshPack, state: D.StatePack,
                       elems: D.ElementPack, cg: D.SolvePack):
        cg.scalars[0] = coef[0]

    uv, faces = make_sheet(1.0, 1.0, n, n)
    model = ClothModel(MeshArrays(uv=uv, x=np.c_[uv, np.zeros(len(uv))], faces=faces),
                       Material())
    dyn = D.ImplicitEuler(model)
    coef = dyn._constants(1 / 30)
    mesh, state = dyn._mesh(), dyn._state()
    arr = ti.ndarray(float, 4)
    sym = ti.graph.Arg(ti.graph.ArgKind.NDARRAY, "a", dtype=ti.f64, ndim=1)
    graphs = {}
    for name, kernel in (("one_array", one_array), ("one_loop", one_loop)):
        builder = ti.graph.GraphBuilder()
        for _ in range(100):
            builder.dispatch(kernel, sym)
        graphs[name] = builder.compile()
    own = _taichis_own_call()
    return {
        "python, no arguments": _timed(lambda: own(no_arguments), repeats),
        "python, one ndarray": _timed(lambda: own(one_array, arr), repeats),
        "python, the dynamics step's arguments (the coefficients and 4 argpacks)":
            _timed(lambda: own(step_arguments, coef, mesh, state, dyn._elems, dyn._cg),
                   repeats),
        "python, one ndarray, a parallel loop over 4 elements":
            _timed(lambda: own(one_loop, arr), repeats),
        "replayed, no arguments": _timed(no_arguments, repeats),
        "replayed, one ndarray": _timed(lambda: one_array(arr), repeats),
        "replayed, the dynamics step's arguments (the coefficients and 4 argpacks)":
            _timed(lambda: step_arguments(coef, mesh, state, dyn._elems, dyn._cg), repeats),
        "compute graph, one ndarray (a graph of 100 launches, per launch)":
            _timed(lambda: graphs["one_array"].run({"a": arr}), max(repeats // 40, 5)) / 100,
        "compute graph, one ndarray, a parallel loop over 4 elements (per launch)":
            _timed(lambda: graphs["one_loop"].run({"a": arr}), max(repeats // 40, 5)) / 100,
    }


def _taichis_own_call():
    """call(kernel, *args): the ``@ti.kernel`` function launched Taichi's own way, without the
    replay of ``cloth/launch.py``."""
    from cloth import launch
    original = launch._installed.get("original")
    if original is None:
        return lambda kernel, *args: kernel(*args)
    return lambda kernel, *args: original(kernel._primal, *args)


def replay_gain(scene, res, warm=20, blocks=12, block=4):
    """ms a frame of ``scene`` (at ``res``, 0: the scene's own) launched Taichi's own way and
    replayed: two simulators stepped in alternating blocks from the same state."""
    from taichi.lang import kernel_impl
    import scenes
    from cloth import launch
    from cloth.simulator import Simulator
    from scenes.common import resolve
    calls = {"taichi": launch._installed["original"], "replayed": kernel_impl.Kernel.__call__}
    sims, ms = {}, {mode: [] for mode in calls}
    try:
        for mode, call in calls.items():
            kernel_impl.Kernel.__call__ = call
            mod = scenes.get(scene)
            cfg = resolve(mod.DEFAULTS, [{"cloth": {"resolution": res}}] if res else [])
            sims[mode] = Simulator(mod.build(cfg), cfg)
            for _ in range(warm):
                sims[mode].step_frame()
        for b in range(blocks):
            for mode in (list(calls) if b % 2 else list(calls)[::-1]):
                kernel_impl.Kernel.__call__ = calls[mode]
                for _ in range(block):
                    t = time.perf_counter()
                    sims[mode].step_frame()
                    ms[mode].append(1e3 * (time.perf_counter() - t))
    finally:
        kernel_impl.Kernel.__call__ = calls["replayed"]
    same = np.array_equal(sims["taichi"].model.positions(), sims["replayed"].model.positions())
    return dict(scene=scene, res=res, faces=sims["taichi"].model.n_faces,
                taichi_ms=statistics.median(ms["taichi"]),
                replayed_ms=statistics.median(ms["replayed"]), identical=bool(same))


def frame_counts(res, frames=20, skip=2):
    """One hanging run at ``res``: medians over frames ``skip``.. of the counts and times."""
    import taichi as ti
    from taichi.lang import kernel_impl
    import scenes
    from cloth.simulator import Simulator
    from scenes.common import resolve
    mod = scenes.get("hanging")
    cfg = resolve(mod.DEFAULTS, [{"cloth": {"resolution": res}}])
    cfg["output"] = dict(cfg["output"], images=False, meshes=False)
    sim = Simulator(mod.build(cfg), cfg)
    launches = [0]
    original = kernel_impl.Kernel.__call__

    def counted(self, *args, **kwargs):
        launches[0] += 1
        return original(self, *args, **kwargs)
    kernel_impl.Kernel.__call__ = counted
    rows = []
    try:
        for f in range(frames):
            launches[0] = 0
            t = time.perf_counter()
            sim.step_frame()
            ms = 1e3 * (time.perf_counter() - t)
            s, d = sim.strain, sim.dynamics
            rows.append(dict(launches=launches[0], ms=ms, dynamics_cg=d.last_cg_iters,
                             al_rounds=s.last_iterations, newton=s.last_newton,
                             pcg=s.last_cg, strain_ms=s.last_ms))
    finally:
        kernel_impl.Kernel.__call__ = original
    med = {k: statistics.median(r[k] for r in rows[skip:]) for k in rows[0]}
    nbytes = 0
    for owner in (sim.model, sim.dynamics, sim.strain._ws):
        for value in vars(owner).values():
            if isinstance(value, (ti.Ndarray, ti.Field)) and hasattr(value, "to_numpy"):
                nbytes += value.to_numpy().nbytes
    mg = sim.strain.implicit_preconditioner()
    return dict(res=res, faces=sim.model.n_faces, vertices=sim.model.n_verts,
                array_mb=nbytes / 1e6, multigrid_levels=list(getattr(mg, "levels", []) or []),
                **med)


def cpu_name():
    try:
        with open("/proc/cpuinfo") as fh:
            names = [line.split(":", 1)[1].strip() for line in fh if line.startswith("model name")]
        return f"{names[0]} ({len(names)} cores)"
    except (OSError, IndexError):
        return platform.machine()


def main():
    from cloth import backend, provenance
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--res", type=int, nargs="*", default=[46, 91, 181])
    ap.add_argument("--replay", nargs="*", default=[], metavar="SCENE:RES",
                    help="scenes to step with and without the replayed launches (RES 0: the "
                         "scene's own)")
    ap.add_argument("--n", type=int, default=91, help="sheet size for the launch costs")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--out", default=None, help="folder for launch_cost.json")
    args = ap.parse_args()
    backend.init("cpu", "f64")
    costs = launch_costs(args.n)
    for what, us in costs.items():
        print(f"{us:8.1f} us  {what}", flush=True)
    counts = []
    for res in args.res:
        c = frame_counts(res, args.frames)
        counts.append(c)
        print(json.dumps(c), flush=True)
    replays = []
    for item in args.replay:
        scene, _, res = item.partition(":")
        replays.append(replay_gain(scene, int(res or 0)))
        print(json.dumps(replays[-1]), flush=True)
    if args.out:
        name = "launch_cost.json" if not replays else "launch_replay.json"
        with open(os.path.join(args.out, name), "w") as fh:
            json.dump(dict(command="python -m benchmarks.launch_cost " + " ".join(sys.argv[1:]),
                           commit=provenance.commit(), date=time.strftime("%Y-%m-%d"),
                           machine=cpu_name(),
                           threads=os.environ.get("TI_CPU_MAX_NUM_THREADS", "all"),
                           launch_us=costs, frames=counts, replay=replays), fh, indent=1)


if __name__ == "__main__":
    main()
