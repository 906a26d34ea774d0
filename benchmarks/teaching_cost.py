"""What the teaching view costs a window frame (docs/teaching.md, issue #36): the hanging
sheet (1152 triangles, mapping) in the real window, settled 40 frames, then paused (so the
simulation's time does not mix in) and drawn 40 frames per configuration, 3 rounds; prints the
median frame, draw, panel and show times. Needs a display:

    LOOM_APP_NO_VSYNC=1 xvfb-run -a -s "-screen 0 1280x800x24" python -m benchmarks.teaching_cost
"""
import numpy as np

CONFIGS = [("base", set(), "warp-strain"), ("binding", set(), "binding"),
           ("axes", {"axes"}, "warp-strain"), ("plot", {"plot"}, "warp-strain"),
           ("all", {"axes", "plot"}, "binding")]


def main(rounds=3, frames=40):
    from cloth import backend
    backend.init("cpu", "f64")
    from ui.app import App
    from ui.state import AppState
    st = AppState.from_scene("hanging", [])
    app = App(st, size=(1280, 800), out_dir="out/teaching_cost")
    for _ in range(40):
        app.frame()
    st.pause()
    res = {}
    for _ in range(rounds):
        for name, overlays, color in CONFIGS:
            st.overlays, app.teach.on, st.color = set(overlays), set(overlays), color
            for _ in range(5):
                app.frame()
            n0 = len(app.frame_times)
            for _ in range(frames):
                app.frame()
            ft, parts = np.array(app.frame_times[n0:]), np.array(app.parts[n0:])
            res.setdefault(name, []).append((np.median(ft), *np.median(parts, axis=0)))
    for name, v in res.items():
        v = np.array(v)
        print(f"{name:8s} frame {np.median(v[:, 0]):6.1f} ms  draw {np.median(v[:, 1]):5.1f}  "
              f"panel {np.median(v[:, 2]):5.1f}  show {np.median(v[:, 3]):5.1f}   "
              f"(rounds: {', '.join(f'{x:.1f}' for x in v[:, 0])})")


if __name__ == "__main__":
    main()
