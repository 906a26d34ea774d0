"""A strain method's first use in a running simulator (what the window's method switch costs),
compiling as a first run on this machine would.

    TI_OFFLINE_CACHE_FILE_PATH=$(mktemp -d) LOOM_BACKGROUND_COMPILE=0 python -m benchmarks.method_switch

Builds the default scene (hanging, mapping), steps one frame, then switches to svd, warp-weft
and back to mapping, timing each first frame after the switch (docs/speed/first_run.md).
"""
import os
import time


def main():
    from cloth import backend
    backend.init("cpu", "f64", first_run_fast=True)
    print(f"compile: {'fast' if backend.fast_compile() else 'optimised'} "
          f"({backend.compile_reason()}); load {os.getloadavg()[0]:.2f}")
    import scenes
    from scenes.common import resolve
    from cloth.simulator import Simulator
    m = scenes.get("hanging")
    cfg = resolve(m.DEFAULTS, [])
    t0 = time.perf_counter()
    sim = Simulator(m.build(cfg), cfg)
    sim.step_frame()
    print(f"build + first frame (mapping): {time.perf_counter() - t0:.1f} s")
    for meth in ("svd", "warp-weft", "mapping"):
        sim.set_method(meth)
        t0 = time.perf_counter()
        sim.step_frame()
        print(f"switch to {meth}: first frame {time.perf_counter() - t0:.1f} s; "
              f"load {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
