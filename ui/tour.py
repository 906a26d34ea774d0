"""The guided demo (``python main.py --tour``): the paper's experiment (Table 1: a 1 m sheet
hanging from its two top corners, warp vertical, warp band +-1 %, weft +-5 %) with svd,
warp-weft and mapping in turn. For each method the sheet settles from the start (the
strain-space plot shows the cloud moving onto the method's boundary), then the tour pauses
at rest on two views with a caption: which constraint binds, and the principal axes over
the threads. Then the same sheet under mapping in two measured fabrics (``FABRICS``, a knit
and a woven, cloth/fabrics.py: material and derived bands), one pause each: where the knit's
limits bind and how far inside its band the woven's own membrane holds it. Captions carry the
numbers measured at that moment.

In a window the tour waits at each pause for "next" (key ``t`` or the caption's button);
headless (or ``--headless``) it writes ``OUT/frames/frame_NNNN.png`` (the whole sequence,
settling every ``SETTLE_EVERY``-th frame, each pause held ``HOLD_S`` seconds in the video),
``OUT/steps/step_NN_METHOD_VIEW.png`` (one picture per pause), ``OUT/captions.md`` and
``OUT/video.mp4``.
"""
import os
import textwrap
from dataclasses import dataclass

import numpy as np

from cloth import metrics
from cloth.strain.families import METHODS

from .overlays import Canvas2D, Layout

SETTLE_FRAMES = 150        # 5 s at 30 fps: the hanging scene's rest check applies from 5 s
SETTLE_EVERY = 3           # settling frames kept in the headless sequence
HOLD_S = 4.0               # a pause's length in the video
SIZE = (1280, 720)
TOUR_LAYOUT = Layout(plot=[(0.515, 0.01, 0.995, 0.60)], key=(0.60, 0.605, 0.995, 0.85),
                     bar=(0.04, 0.06, 0.40, 0.022), view_x=(0.04, 0.48), view_y=(0.05, 0.82))
CAPTION_BOX = (0.0, 0.855, 1.0, 1.0)


@dataclass
class Step:
    method: str
    view: str              # "binding": binding map + plot; "axes": principal axes + plot
    fabric: str = None     # a fabric record (cloth/fabrics.py) the sheet is restarted in


FABRICS = ("cotton-jersey", "denim")     # a knit and a woven: the comparison's two fabrics
# the stages the sheet settles in, each (method, fabric or None), and the pauses after each
STAGES = [(m, None) for m in METHODS] + [("mapping", f) for f in FABRICS]
STEPS = ([Step(m, v) for m in METHODS for v in ("binding", "axes")]
         + [Step("mapping", "binding", f) for f in FABRICS])


def stage_steps(stage):
    return [s for s in STEPS if (s.method, s.fabric) == stage]


def start_stage(st, stage):
    """The app state ``st`` restarted for ``stage``: the method, and the fabric if any."""
    method, fabric = stage
    st.switch_method(method)
    if fabric:
        st.set_fabric(fabric)
    st.reset()


def step_name(k, step):
    return f"step_{k:02d}_{step.method}_{step.fabric or step.view}.png"


def facts(sim):
    """The numbers the captions quote, from ``cloth.metrics`` and the solver's
    multipliers."""
    from .teaching import binding
    m = sim.model
    st = sim.face_strains()
    idx = binding(sim)
    names = metrics.CONSTRAINT_NAMES[sim.method]
    counts = {names[k]: int(np.sum(idx == k)) for k in range(len(names)) if np.any(idx == k)}
    F = metrics.deformation_gradients(m.positions(), m.faces,
                                      metrics.material_Dm_inv(m.uv, m.faces))
    _, V, _ = metrics.principal_stretches(F)
    cos = np.abs(np.einsum("nk,nk->n", m.grain[:, :, 0], V[:, :, 0]))
    angle = np.degrees(np.arccos(np.clip(cos, 0.0, 1.0)))
    bound = idx >= 0
    own = sim.own_violation()
    bands = sim.bands()
    warp = bands["warp"]
    return {"bands": {k: [100 * float(e) for e in v] for k, v in bands.items()},
            "n": m.n_faces, "t": sim.time, "bound": int(bound.sum()), "counts": counts,
            "warp": 100 * float(st["warp"].max()), "weft": 100 * float(st["weft"].max()),
            "bias_lo": 100 * float(st["bias"].min()), "bias_hi": 100 * float(st["bias"].max()),
            "p1": 100 * float(st["principal_max"].max()),
            "angle": float(np.mean(angle[bound])) if bound.any() else 0.0,
            "ratio": float(st["warp"].max() / warp[1]),
            "own": float(own.max()) if own is not None else 0.0,
            "ke": metrics.kinetic_energy(m.velocities(), m.mass)}


def _counts(f):
    return ", ".join(f"{name} on {k}" for name, k in
                     sorted(f["counts"].items(), key=lambda t: -t[1])) or "none"


def fabric_caption(step, f):
    """A fabric pause's caption body: the derived bands, the strains reached, what binds."""
    b = f["bands"]
    body = (f"fabric {step.fabric} (cloth/fabrics.py: material and bands from its data; warp "
            f"+-{b['warp'][1]:.3g} %, weft +-{b['weft'][1]:.3g} %). Thread strains reach warp "
            f"{f['warp']:+.2f} %, weft {f['weft']:+.2f} %. Binding: {_counts(f)}")
    if f["bound"]:
        body += (f" of {f['n']} triangles: the limits hold the sheet where the pins pull it "
                 "(the plot: the cloud reaches its box).")
    else:
        body += (f": its own membrane holds the sheet at {100 * f['ratio']:.0f} % of its warp "
                 "band, and the limits never act (the plot: a dot in its box).")
    return body


def caption(step, f):
    """The caption of a pause (``f``: ``facts`` at that moment)."""
    head = (f"{step.method} at t = {f['t']:.1f} s (kinetic energy {f['ke']:.1e} J; own "
            f"constraints held to {f['own']:.1e}). ")
    if step.fabric:
        body = fabric_caption(step, f)
    elif step.method == "svd" and step.view == "binding":
        body = ("svd bounds the principal stretches whatever their direction: eta1 - 1 in the "
                "warp band (+-1 %), eta2 - 1 in the weft band (+-5 %). Binding: "
                f"{_counts(f)} of {f['n']} triangles; in the principal plane (left) they sit "
                "on the box's right edge.")
    elif step.method == "svd":
        body = ("Principal axes over the threads. Since eta1 is the largest stretch in any "
                "direction, holding it to 1 % holds every direction to 1 %: warp max "
                f"{f['warp']:+.2f} %, weft max {f['weft']:+.2f} % although the weft band is "
                "5 %. svd is isotropic: it cannot tell warp from weft.")
    elif step.method == "warp-weft" and step.view == "binding":
        body = ("warp-weft bounds the stretch along the threads (warp +-1 %, weft +-5 %) and "
                f"the bias shear (bias strain {f['bias_lo']:+.2f}..{f['bias_hi']:+.2f} %). "
                f"Binding: {_counts(f)}. Right: the thread plane, the cloud pressed on the "
                "warp edge of its box.")
    elif step.method == "warp-weft":
        body = ("Principal axes: only the thread directions are bounded, so the largest "
                f"principal strain reaches {f['p1']:+.2f} % where the axes turn from the "
                f"threads (binding triangles: major axis {f['angle']:.0f} deg from the warp on "
                f"average); weft max {f['weft']:+.2f} %.")
    elif step.view == "binding":
        body = ("mapping bounds each principal strain mapped onto warp and weft, "
                "c (eta - 1) with c = |e . v|, by that thread's band (A: the major principal "
                f"axis, B: the minor). Binding: {_counts(f)}. Right: the mapped points stay in "
                f"the box; the thread strains (dark) pass it: warp max {f['warp']:+.2f} % = "
                f"{f['ratio']:.2f} x the band (the bound is sqrt 2 = 1.41 at 45 deg).")
    else:
        body = ("Principal axes: where the mapping binds, the major axis lies "
                f"{f['angle']:.0f} deg from the warp on average; there c < 1 lets the "
                "principal stretch pass the warp band: the larger deformation and richer "
                "wrinkles of the paper's Table 1.")
    return head + body


def provenance():
    """The page's line of where it came from: the command, the code's commit, the date and
    the machine."""
    import platform
    import sys
    import time

    from cloth.provenance import commit
    args = " ".join(sys.argv[1:])
    return (f"Made by `python main.py {args}` at commit {commit()} on "
            f"{time.strftime('%Y-%m-%d')} "
            f"({os.cpu_count()} cores, {platform.machine()}); the pictures are `steps/`.")


def draw_caption(renderer, text, box=CAPTION_BOX, step_label=""):
    """A caption banner on the canvas (text as rectangles, so captures keep it)."""
    cv = Canvas2D(renderer)
    x0, y0, x1, y1 = box
    px, py = cv.px
    cv.rect(x0, y0, x1, y1, np.array([0.13, 0.14, 0.18]))
    width = int((x1 - x0) / px / 6.6) - 4
    lines = textwrap.wrap(text, width)
    if step_label:
        cv.text(step_label, x1 - 8 * px, y1 - 6 * py, np.array([0.75, 0.80, 0.90]), 12,
                anchor="right")
    for k, line in enumerate(lines[:int((y1 - y0) / py / 16)]):
        cv.text(line, x0 + 10 * px, y1 - (8 + 16 * k) * py, np.array([0.96, 0.96, 0.96]), 13)
    cv.flush("caption")


def _state(args):
    """The tour's app state: the hanging scene (--resolution, --set, --config apply)."""
    import scenes
    from cloth.config import load_toml, parse_assignment
    from scenes.common import resolve

    from .state import AppState
    overrides = [load_toml(args.config)] if args.config else []
    overrides += [parse_assignment(s) for s in args.set]
    if args.resolution:
        overrides.append({"cloth": {"resolution": args.resolution}})
    resolve(scenes.get("hanging").DEFAULTS, overrides)      # bad input stops here
    return AppState.from_scene("hanging", overrides)


def _apply(st, step):
    st.color = "binding" if step.view == "binding" else "shading"
    st.overlays = {"plot"} | ({"axes"} if step.view == "axes" else set())


def run_tour(args, headless):
    from cloth.config import ConfigError
    try:
        st = _state(args)
    except (KeyError, ConfigError, ValueError) as err:
        import sys
        print(f"loom: error: {err}", file=sys.stderr)
        return 2
    settle = args.frames or SETTLE_FRAMES
    if headless:
        out = args.out or os.path.join("out", "tour")
        return TourRecorder(st, out, settle, quiet=args.quiet).run()
    from .app import run_tour_window
    return run_tour_window(st, settle)


class TourRecorder:
    """The tour offscreen: frames, one picture per pause, the captions and a video."""

    def __init__(self, st, out, settle, quiet=False):
        self.st, self.out, self.settle, self.quiet = st, out, settle, quiet
        self.count = 0

    def _draw(self, text, label):
        from .render import draw_simulation
        st, r = self.st, self.renderer
        draw_simulation(r, st.sim, st.color, teach=self.teach, layout=TOUR_LAYOUT)
        draw_caption(r, text, step_label=label)
        return r.image(annotate=False)

    def _emit(self, img, writer, repeat=1):
        import imageio.v2 as imageio
        imageio.imwrite(os.path.join(self.out, "frames", f"frame_{self.count:04d}.png"), img)
        self.count += 1
        for _ in range(repeat):
            writer.append_data(img)

    def run(self):
        import glob

        import imageio.v2 as imageio

        from .overlays import TeachingLayer
        from .progress import Progress
        from .render import ClothRenderer, open_window
        st = self.st
        window = open_window("Loom tour (offscreen)", SIZE, show_window=False)
        self.renderer = ClothRenderer(window, st.sim.setup.camera)
        self.teach = TeachingLayer(("plot",))
        self.teach.fixed_axes = True
        for sub in ("frames", "steps"):
            os.makedirs(os.path.join(self.out, sub), exist_ok=True)
            for p in glob.glob(os.path.join(self.out, sub, "*.png")):
                os.remove(p)
        fps = st.settings.sim.fps
        captions = ["# Loom tour: the paper's Table 1 with the three methods, and two "
                    "fabrics\n", provenance() + "\n"]
        total = len(STAGES) * self.settle
        progress = None if self.quiet else Progress(total)
        done, k = 0, 0
        verdicts = []         # (method, ok, message): the scene's final check after settling
        with imageio.get_writer(os.path.join(self.out, "video.mp4"), fps=fps,
                                macro_block_size=8, quality=7) as writer:
            for stage in STAGES:
                method, fabric = stage
                label = f"{method}, {fabric}" if fabric else method
                start_stage(st, stage)
                st.color, st.overlays = "binding", {"plot"}
                self.teach.on = set(st.overlays)
                r = self.renderer
                r.set_camera_cfg(st.sim.setup.camera)
                r.orbit.fit(st.sim.model.positions(), r.aspect, TOUR_LAYOUT.view_x,
                            TOUR_LAYOUT.view_y)
                for f in range(self.settle + 1):
                    if f:
                        st.sim.step_frame()
                        done += 1
                        if progress:
                            progress.update(done, f"{label}: settling")
                    if f % SETTLE_EVERY == 0:
                        text = (f"{label}: the sheet settles from the start (t = "
                                f"{st.sim.time:.2f} s); each triangle is a point in strain "
                                "space, coloured by the constraint that binds it.")
                        self._emit(self._draw(text, f"{label}  settling"), writer)
                verdicts.append((label,) + st.sim.setup.check_final(st.sim))
                fa = facts(st.sim)
                for step in stage_steps(stage):
                    k += 1
                    _apply(st, step)
                    self.teach.on = set(st.overlays)
                    text = caption(step, fa)
                    img = self._draw(text, f"step {k}/{len(STEPS)}")
                    name = step_name(k, step)
                    imageio.imwrite(os.path.join(self.out, "steps", name), img)
                    self._emit(img, writer, repeat=int(HOLD_S * fps))
                    title = f"{method}, {step.fabric or step.view}"
                    captions.append(f"{k}. **{title}**: {text}\n\n"
                                    f"   ![{title}](steps/{name})\n")
        if progress:
            progress.close()
        with open(os.path.join(self.out, "captions.md"), "w") as fh:
            fh.write("\n".join(captions))
        print(f"loom: wrote the tour to {self.out}/ (frames/, steps/, captions.md, video.mp4)")
        for method, ok, message in verdicts:
            print(f"final check ({method}): {'ok' if ok else 'FAILED'} ({message})")
        return 0 if all(ok for _, ok, _ in verdicts) else 5     # main.EXIT_CHECK_FAILED
