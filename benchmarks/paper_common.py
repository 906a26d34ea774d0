"""What the paper reproductions share (``reproduce_paper`` for Table 1, ``table2`` for Table 2):
the methods and band settings, running a scene to rest, the per-run measures, and the picture
pair. Kept apart so that the two table modules import it, not each other."""
import time

from cloth.strain.families import METHODS  # noqa: F401 (the reproductions' method list)
BANDS = {
    "V1H5": {"warp": [-0.01, 0.01], "weft": [-0.05, 0.05]},   # vertical 1 %, horizontal 5 %
    "V5H1": {"warp": [-0.05, 0.05], "weft": [-0.01, 0.01]},   # swapped
}


def settle(module, overrides, frames, prepare=None):
    """Run a scene to rest; returns (sim, ms per frame, max own violation over the last frames).
    ``prepare(sim)``, if given, runs before the first frame (e.g. a perturbation)."""
    import numpy as np
    from cloth.simulator import Simulator
    from scenes.common import resolve
    cfg = resolve(module.DEFAULTS, overrides)
    sim = Simulator(module.build(cfg), cfg)
    if prepare is not None:
        prepare(sim)
    sim.step_frame()                           # compile outside the timing
    times, viol = [], []
    for k in range(frames - 1):
        t0 = time.perf_counter()
        sim.step_frame()
        times.append(1000 * (time.perf_counter() - t0))
        if k >= frames - 11:
            viol.append(sim.metrics_row()["own_violation_max"])
    return sim, float(np.median(times)), float(max(viol) if viol else 0.0)


def measure(sim):
    import numpy as np
    from cloth import metrics
    m = sim.model
    x = m.positions()
    st = metrics.face_strains(x, m.uv, m.faces, m.grain)
    row = sim.metrics_row()
    out = {}
    for key in ("warp", "weft"):
        s = st[key]
        out[f"{key}_max"] = float(s.max())
        out[f"{key}_rms"] = metrics.weighted_rms(s, m.rest_area)
        out[f"{key}_p95"] = metrics.percentile(s, 95)
    out["bias_max"] = float(np.abs(st["bias"]).max())
    out["own_violation_max"] = row["own_violation_max"]
    # How far the warp and weft strains lie outside their bands (only warp-weft bounds them
    # directly; metrics.csv reports the strains and the method's own violation instead).
    bands = sim.bands()
    for key in ("warp", "weft"):
        out[f"{key}_violation_max"] = float(np.max(metrics.band_violation(st[key], bands[key])))
    ef = m.edge_faces.to_numpy()[: m.n_edges]
    eo = m.edge_opp.to_numpy()[: m.n_edges]
    out.update(metrics.wrinkle_measures(x, m.faces, m.edges, ef, eo, m.uv))
    out["height"] = float(x[:, 1].max() - x[:, 1].min())
    out["width"] = float(x[:, 0].max() - x[:, 0].min())
    out["kinetic_energy"] = row["kinetic_energy"]
    out["sl_iterations"] = row["sl_iterations"]
    return out


def render_pair(renderer, sim):
    """Shaded and warp-strain images of the current state, side by side."""
    import numpy as np
    from ui.render import draw_simulation
    imgs = []
    for mode in ("shading", "warp-strain"):
        draw_simulation(renderer, sim, mode)
        imgs.append(renderer.image())
    return np.concatenate(imgs, axis=1)


def label(img, text):
    from PIL import Image, ImageDraw
    im = Image.fromarray(img)
    ImageDraw.Draw(im).text((8, 6), text, fill=(20, 20, 20))
    import numpy as np
    return np.asarray(im)
