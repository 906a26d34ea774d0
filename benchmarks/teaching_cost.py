"""What the teaching view costs a window frame (docs/teaching.md, issue #36): the hanging
sheet (1152 triangles, mapping) in the real window, settled 40 frames, then paused (so the
simulation's time does not mix in) and drawn 40 frames per configuration, 3 rounds; prints the
median frame, draw, panel and show times. The last configuration moves a scripted cursor over
the cloth every frame (hover looked up every frame). Needs a display:

    LOOM_APP_NO_VSYNC=1 xvfb-run -a -s "-screen 0 1280x800x24" python -m benchmarks.teaching_cost
"""
import numpy as np

CONFIGS = [("base", set(), "warp-strain"), ("binding", set(), "binding"),
           ("axes", {"axes"}, "warp-strain"), ("plot", {"plot"}, "warp-strain"),
           ("all", {"axes", "plot"}, "binding"), ("hover", {"axes", "plot"}, "binding")]
# "hover": everything on and the cursor moving over the cloth every frame (a scripted cursor
# across the middle of the cloth's screen box), so the hovered face is looked up every frame.


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
    x = st.world_positions(0)
    scr = app.renderer.orbit.project(x, app.renderer.aspect)[0]
    lo, hi = np.percentile(scr, 20, axis=0), np.percentile(scr, 80, axis=0)
    still, step = app.window.get_cursor_pos, [0]

    def sweep():
        step[0] += 1
        return tuple(lo + (hi - lo) * np.array([(0.037 * step[0]) % 1, (0.061 * step[0]) % 1]))
    res = {}
    for _ in range(rounds):
        for name, overlays, color in CONFIGS:
            st.overlays, app.teach.on, st.color = set(overlays), set(overlays), color
            app.window.get_cursor_pos = sweep if name == "hover" else still
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
