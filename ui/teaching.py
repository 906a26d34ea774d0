"""The teaching view's content, numpy only (headless tools and tests use it without a window;
``ui/overlays.py`` draws it with GGUI):

- the principal-axes overlay: per glyph site (a triangle; thinned to about ``MAX_SITES`` on
  fine meshes), the two principal stretch directions as short strokes whose length and colour
  give the stretch, over thin warp and weft thread strokes;
- the binding-constraint map: each triangle coloured by which of the current method's
  constraints binds (largest positive multiplier of the solver), with a key;
- the strain-space plot: every triangle as a point in the plane of its principal strains and
  in the plane of its thread (warp, weft) strains, or under mapping its mapped strains, with
  the current method's feasible box.

Every number comes from ``cloth.metrics`` (one definition): the points from
``strain_space``, the boxes from ``feasible_region``, the binding constraint from
``binding_constraints``. Nothing here changes a simulator: it reads positions, multipliers
(``StrainLimiter.face_state``) and bands.
"""
from dataclasses import dataclass, field

import numpy as np

from cloth import metrics

from .colormap import FREE, SEQ, _ramp, binding_colors, strain_bands

MAX_SITES = 400            # at most this many glyph sites (thinned on finer meshes)
GLYPH_STRETCH = SEQ
GLYPH_COMPRESSION = [(0.0, np.array([0.70, 0.85, 0.98])), (1.0, np.array([0.05, 0.15, 0.60]))]
WHAT_BINDS = {
    "svd": "eta1 = the larger principal stretch (warp band), eta2 the smaller (weft band)",
    "warp-weft": "stretch along the warp and weft threads, and the bias (45 deg) shear",
    "mapping": "principal stretch mapped onto warp / weft; A = the major principal axis (eta1), B the minor",
}


# -- binding map ----------------------------------------------------------------------------
def binding(sim):
    """Per face, the index into ``metrics.CONSTRAINT_NAMES[method]`` of the constraint that
    binds, -1 where none does; None without a method."""
    if sim.strain is None or not sim.stage("strain_limit").enabled:
        return None
    names = metrics.CONSTRAINT_NAMES[sim.method]
    lam = sim.strain.face_state()["lam"]
    return metrics.binding_constraints(lam, len(names))


# -- principal-axes overlay -----------------------------------------------------------------
def glyph_sites(uv, faces, max_sites=MAX_SITES):
    """Faces that carry a glyph and the glyph's size (material length, m): the face nearest
    the centre of each cell of a square grid over the material. The cell is a whole number
    of triangle legs (sqrt(2 x median rest area)), the smallest that gives at most
    ``max_sites`` cells, so the glyphs of a regular sheet sit one per k x k squares without
    beating against its grid (hanging at 1152 faces: k = 2, 144 glyphs; 4608 faces: k = 3)."""
    uv, faces = np.asarray(uv, float), np.asarray(faces)
    area = metrics.material_areas(uv, faces)
    cen = uv[faces].mean(axis=1)
    leg = float(np.sqrt(2.0 * np.median(area)))
    k = max(1, int(np.ceil(np.sqrt(area.sum() / max_sites) / leg - 1e-9)))
    h = k * leg
    lo = uv.min(axis=0)
    cell = np.floor((cen - lo) / h).astype(np.int64)
    dist = np.linalg.norm(cen - (lo + (cell + 0.5) * h), axis=1)
    key = cell[:, 0] * (cell[:, 1].max() + 1) + cell[:, 1]
    order = np.lexsort((dist, key))
    first = np.r_[True, key[order][1:] != key[order][:-1]]
    return np.sort(order[first]), h


def axis_glyphs(x, faces, Dm_inv, grain, sites, size, bands):
    """The overlay's strokes as segment end points (world, m) with colours:
    ``principal`` (2S, 2, 3) and its colours (2S, 3): per site two strokes through the face's
    centroid along the world images U_1, U_2 of the principal directions, with e the widest
    band edge: length size x (0.3 + 0.7 min(1, |eta - 1| / e)), coloured by |eta - 1| / e
    from yellow (0) over orange to dark red (e and beyond) in stretch, light to dark blue in
    compression (``GLYPH_STRETCH``, ``GLYPH_COMPRESSION``); ``grain`` (2S, 2, 3): the warp and weft threads
    F e through the centroid, ``size`` long in material length (they stretch with the
    cloth)."""
    x = np.asarray(x, float)
    f = np.asarray(faces)[sites]
    F = metrics.deformation_gradients(x, f, np.asarray(Dm_inv)[sites])
    eta, _, U = metrics.principal_stretches(F)
    strain = eta - 1.0
    warp, weft, _ = strain_bands(bands)
    lo, hi = min(warp[0], weft[0]), max(warp[1], weft[1])
    e = max(hi, -lo, 1e-4)
    t = np.minimum(1.0, np.abs(strain) / e)
    length = size * (0.3 + 0.7 * t)                                              # (S, 2)
    c = x[f].mean(axis=1)
    half = 0.5 * length[:, :, None] * np.swapaxes(U, 1, 2)                     # (S, 2, 3)
    principal = np.stack([c[:, None] - half, c[:, None] + half], axis=2).reshape(-1, 2, 3)
    colors = np.where((strain >= 0).reshape(-1, 1), _ramp(t.reshape(-1), GLYPH_STRETCH),
                      _ramp(t.reshape(-1), GLYPH_COMPRESSION))
    threads = F @ np.asarray(grain)[sites]                                      # (S, 3, 2)
    tw = 0.5 * size * np.swapaxes(threads, 1, 2)                                 # (S, 2, 3)
    grain_seg = np.stack([c[:, None] - tw, c[:, None] + tw], axis=2).reshape(-1, 2, 3)
    return {"principal": principal, "principal_colors": colors, "grain": grain_seg,
            "centroids": c}


# -- strain-space plot ----------------------------------------------------------------------
NICE = (0.005, 0.01, 0.015, 0.02, 0.03, 0.04, 0.05, 0.06, 0.08, 0.1, 0.15, 0.2, 0.3, 0.5,
        0.75, 1.0, 1.5, 2.0)


def nice_extent(values, band=None, floor=0.01):
    """A plot range (lo, hi) that shows the band (if given) with room on both sides and
    nearly all values (99.5 %), at least +-``floor`` / 4, its ends rounded up to the steps of
    ``NICE`` (it changes in steps, so the plot does not wobble frame to frame)."""
    v = np.asarray(values, float).ravel()
    band = (0.0, 0.0) if band is None else band
    lo_need = min(1.25 * band[0], -0.25 * floor)
    hi_need = max(1.25 * band[1], 0.25 * floor)
    if v.size:
        lo_need = min(lo_need, float(np.percentile(v, 0.25)))
        hi_need = max(hi_need, float(np.percentile(v, 99.75)))

    def up(t):
        return next((n for n in NICE if n >= t), NICE[-1])
    return -up(-lo_need), up(hi_need)


@dataclass
class Panel:
    """One plane of the strain-space plot. ``points`` (n, 2) strains with ``colors`` and
    ``radius`` (fraction of the panel's height); ``held`` the points the method's own
    constraints bound (what its ``region`` must contain); ``faint`` points drawn small and
    grey behind them; ``region`` the method's feasible box or None; ``reference`` a box drawn
    as a thin outline (bands that this method does not bound in this plane); ``diagonal``
    draws y = x."""
    title: str
    xlabel: str
    ylabel: str
    xlim: tuple
    ylim: tuple
    points: np.ndarray
    colors: np.ndarray
    faces: np.ndarray              # the face of each point (for highlighting)
    region: tuple = None
    reference: tuple = None
    faint: np.ndarray = None
    diagonal: bool = False
    note: str = ""
    extra: list = field(default_factory=list)     # further lines under the title

    def to_unit(self, pts):
        """Strains -> panel coordinates in [0, 1]^2 (clamped to the frame)."""
        pts = np.asarray(pts, float).reshape(-1, 2)
        u = (pts[:, 0] - self.xlim[0]) / (self.xlim[1] - self.xlim[0])
        v = (pts[:, 1] - self.ylim[0]) / (self.ylim[1] - self.ylim[0])
        return np.clip(np.stack([u, v], axis=1), 0.0, 1.0)


def strain_plot(method, x, faces, Dm_inv, grain, bands, iso=0.0, bind=None, held=None):
    """The two panels of the strain-space plot for one simulator state.

    Left, the principal plane (eta1 - 1, eta2 - 1): svd's box (eta1 in the warp band, eta2
    in the weft band). Right, the grain plane: the thread strains (warp, weft) with
    warp-weft's box (its bias constraint is an interval, given in the title); under mapping
    the mapped strains of both principal pairs with mapping's box, the thread strains faint
    behind them (they may leave the box, up to sqrt 2 x at 45 degrees). Points are coloured
    by the face's binding constraint (``bind``, as ``binding``).

    ``held``: a dict kept between calls (the tour keeps one per method) whose axes only grow:
    each panel's range is the union of its ranges so far, so a cloud settling onto its box
    does so on axes that hold still once it has spread, and the pauses of one method share
    them."""
    warp, weft, bias = strain_bands(bands)
    calls = iter(range(4))

    def extent(values, band):
        lo, hi = nice_extent(values, band)
        if held is None:
            return lo, hi
        key = next(calls)
        old = held.get(key, (lo, hi))
        held[key] = (min(lo, old[0]), max(hi, old[1]))
        return held[key]
    b = {"warp": warp, "weft": weft, "bias": bias}
    sp = metrics.strain_space(method if method in metrics.CONSTRAINT_NAMES else "none",
                              x, faces, Dm_inv, grain, b, iso)
    n = len(sp["principal"])
    idx = np.full(n, -1) if bind is None else np.asarray(bind)
    rgb, _ = binding_colors(method, idx if bind is not None else None, n)
    ids = np.arange(n)
    own = method if method in metrics.CONSTRAINT_NAMES else None

    svd = own == "svd"
    pr = Panel("principal strains", "eta1 - 1", "eta2 - 1",
               extent(sp["principal"][:, 0], warp if svd else None),
               extent(sp["principal"][:, 1], weft if svd else None),
               sp["principal"], rgb, ids, diagonal=True)
    if own == "svd":
        pr.region = metrics.feasible_region("svd", "principal", b)
        pr.note = "svd's box: eta1 in warp band, eta2 in weft band"
    else:
        pr.note = "no box: " + ("the cloth is free" if own is None else
                                f"{own} does not bound the principal strains")

    if own == "mapping":
        m = sp["mapped"]                                       # (n, pair, (warp, weft))
        names = metrics.CONSTRAINT_NAMES["mapping"]
        pair_of = np.array([("via B" in nm) for nm in names], int)
        pts = m.reshape(-1, 2)
        cols = np.tile(FREE, (2 * n, 1))
        for j in range(2):
            on = (idx >= 0) & (pair_of[np.maximum(idx, 0)] == j)
            cols[2 * np.nonzero(on)[0] + j] = rgb[on]
        allv = np.concatenate([pts, sp["grain"]])
        gr = Panel("mapped strains c(eta - 1)", "along warp", "along weft",
                   extent(allv[:, 0], warp), extent(allv[:, 1], weft), pts, cols,
                   np.repeat(ids, 2), region=metrics.feasible_region("mapping", "mapped", b),
                   faint=sp["grain"])
        gr.note = "mapping's box; dark dots: thread strains (up to sqrt 2 x band)"
    else:
        gr = Panel("thread strains", "warp", "weft", extent(sp["grain"][:, 0], warp),
                   extent(sp["grain"][:, 1], weft), sp["grain"], rgb, ids)
        if own == "warp-weft":
            gr.region = metrics.feasible_region("warp-weft", "grain", b)
            lo, hi = metrics.feasible_region("warp-weft", "bias", b)
            gr.note = "warp-weft's box"
            gr.extra.append(f"bias {100 * sp['bias'].min():+.2f}..{100 * sp['bias'].max():+.2f} %"
                            f" in band {100 * lo:+.1f}..{100 * hi:+.1f}")
        else:
            gr.reference = (warp, weft)
            gr.note = "outline: the bands, " + ("not bounded by svd" if own == "svd"
                                                 else "not enforced")
    return [pr, gr], sp


def panels_inside(panels, tol):
    """For tests and read-outs: per panel with a region, the largest distance (strain) by
    which a point lies outside it (0 if every point is inside)."""
    out = []
    for p in panels:
        if p.region is None:
            continue
        (x0, x1), (y0, y1) = p.region
        pts = np.asarray(p.points)
        d = np.maximum.reduce([x0 - pts[:, 0], pts[:, 0] - x1, y0 - pts[:, 1], pts[:, 1] - y1,
                               np.zeros(len(pts))])
        out.append((p.title, float(d.max()) if len(d) else 0.0))
    return out


# -- text as rectangles (GGUI draws no text into the canvas) --------------------------------
_TEXT_CACHE = {}


def text_runs(text, size=12):
    """The dark pixels of ``text`` in Pillow's default font as rectangles
    (row0, row1, col0, col1) (rows row0 .. row1 - 1, columns col0 .. col1 - 1) from the
    top-left, and the bitmap's (width, height): drawn as canvas rectangles, labels then appear
    in the window and in captures alike. A row's horizontal runs are merged with the same runs
    of the rows below (the strokes of the letters), about half as many rectangles as runs
    (each costs GGUI two triangles every frame)."""
    key = (text, size)
    if key not in _TEXT_CACHE:
        from PIL import Image, ImageDraw, ImageFont
        try:
            font = ImageFont.load_default(size=size)
        except TypeError:          # Pillow < 10.1: one bitmap size
            font = ImageFont.load_default()
        l, t, r, b = font.getbbox(text)
        w, h = max(1, r - l + 2), max(1, b - t + 2)
        img = Image.new("L", (w, h), 0)
        ImageDraw.Draw(img).text((1 - l, 1 - t), text, fill=255, font=font)
        a = np.asarray(img) > 110
        rects, open_runs = [], {}          # (col0, col1) -> first row of the open rectangle
        for row in range(h + 1):
            runs = set()
            if row < h:
                d = np.diff(np.r_[False, a[row], False].astype(np.int8))
                runs = set(zip(np.nonzero(d == 1)[0].tolist(), np.nonzero(d == -1)[0].tolist()))
            for run in [k for k in open_runs if k not in runs]:
                rects.append((open_runs.pop(run), row, *run))
            for run in runs:
                open_runs.setdefault(run, row)
        _TEXT_CACHE[key] = (np.array(sorted(rects), float).reshape(-1, 4), (w, h))
    return _TEXT_CACHE[key]
