"""Colours of the cloth: the palette, the colour modes (strain heat maps, violation, triangle
size) and their legends. Numpy only, so headless tools and tests use it without a window;
``ui/render.py`` draws what it returns.

Heat maps are diverging (blue negative, white zero, red positive) and centred on zero; the
colour steps from pale to saturated at the band edges, so where a face leaves its strain band
shows on the cloth as a contour, and the colour bar marks the edges with ticks. The strains
and violations come from ``cloth.metrics`` (one definition).
"""
from dataclasses import dataclass, field

import numpy as np

from cloth import metrics

COLOR_MODES = ("shading", "warp-strain", "weft-strain", "bias-strain", "principal-strain",
               "violation", "size", "binding")
CLOTH_FRONT = np.array([0.80, 0.45, 0.30])
OBSTACLE = np.array([0.62, 0.66, 0.72])
PLAIN = np.array([0.86, 0.86, 0.84])      # the cloth under the principal-axes strokes
GROUND = np.array([0.55, 0.57, 0.60])
BACKGROUND = (0.96, 0.96, 0.97)
WIRE = (0.15, 0.15, 0.18)

# Diverging ramp (value / edge, colour): pale up to the band edge, saturated past it.
WHITE = np.array([0.95, 0.95, 0.95])
PALE_RED, RED, DARK_RED = np.array([0.97, 0.66, 0.55]), np.array([0.86, 0.22, 0.14]), \
    np.array([0.45, 0.0, 0.05])
PALE_BLUE, BLUE, DARK_BLUE = np.array([0.62, 0.74, 0.95]), np.array([0.17, 0.38, 0.86]), \
    np.array([0.04, 0.08, 0.42])
# Sequential ramp (violation, triangle size).
SEQ = [(0.0, np.array([0.99, 0.93, 0.55])), (0.5, np.array([0.93, 0.45, 0.15])),
       (1.0, np.array([0.45, 0.02, 0.10]))]
SEQ_SIZE = [(0.0, np.array([0.23, 0.30, 0.75])), (0.5, np.array([0.55, 0.80, 0.60])),
            (1.0, np.array([0.98, 0.85, 0.25]))]
INSIDE = np.array([0.82, 0.86, 0.88])     # violation mode: faces inside every band
# The binding map (docs/teaching.md): which of the method's constraints binds, by name
# (``metrics.CONSTRAINT_NAMES``): upper bounds warm (stretch held), lower bounds cool
# (compression held), grey where none binds.
FREE = np.array([0.70, 0.72, 0.75])
BINDING_COLORS = {
    "eta1 max": (0.84, 0.15, 0.12), "eta1 min": (0.15, 0.35, 0.85),
    "eta2 max": (0.96, 0.60, 0.10), "eta2 min": (0.10, 0.65, 0.70),
    "warp max": (0.84, 0.15, 0.12), "warp min": (0.15, 0.35, 0.85),
    "weft max": (0.96, 0.60, 0.10), "weft min": (0.10, 0.65, 0.70),
    "bias max": (0.55, 0.20, 0.70), "bias min": (0.25, 0.65, 0.25),
    "warp via A max": (0.84, 0.15, 0.12), "warp via A min": (0.15, 0.35, 0.85),
    "warp via B max": (0.90, 0.35, 0.65), "warp via B min": (0.45, 0.65, 0.95),
    "weft via A max": (0.96, 0.60, 0.10), "weft via A min": (0.10, 0.65, 0.70),
    "weft via B max": (0.62, 0.45, 0.15), "weft via B min": (0.25, 0.65, 0.25),
}


def diverging(values, scale):
    """Blue (negative) - white (0) - red (positive) colours for ``values / scale`` in [-1, 1]."""
    t = np.clip(np.asarray(values) / max(scale, 1e-12), -1.0, 1.0)[:, None]
    white = np.array([0.95, 0.95, 0.95])
    red, blue = np.array([0.80, 0.10, 0.10]), np.array([0.15, 0.30, 0.85])
    return np.where(t >= 0, white + t * (red - white), white - t * (blue - white))


def _ramp(t, stops):
    t = np.clip(np.asarray(t, float), 0.0, 1.0)
    pos = np.array([s[0] for s in stops])
    cols = np.array([s[1] for s in stops])
    return np.stack([np.interp(t, pos, cols[:, c]) for c in range(3)], axis=-1)


def band_diverging(values, band):
    """Zero-centred diverging colours with a step at the band edges ``band = (lo, hi)``
    (lo < 0 < hi): white at 0, pale up to the edge, saturated from the edge to full colour at
    twice the edge. Returns (N, 3)."""
    lo, hi = band
    hi = max(hi, 1e-6)
    lo = min(lo, -1e-6)
    s = np.asarray(values, float)
    out = np.empty(s.shape + (3,))
    pos = s >= 0
    tp = s[pos] / hi                                  # 1 at the band edge
    out[pos] = np.where((tp <= 1.0)[:, None], _ramp(tp, [(0, WHITE), (1, PALE_RED)]),
                        _ramp(tp - 1.0, [(0, RED), (1, DARK_RED)]))
    tn = s[~pos] / lo
    out[~pos] = np.where((tn <= 1.0)[:, None], _ramp(tn, [(0, WHITE), (1, PALE_BLUE)]),
                         _ramp(tn - 1.0, [(0, BLUE), (1, DARK_BLUE)]))
    return out


@dataclass
class Legend:
    """What a colour mode means: a colour bar from ``lo`` to ``hi`` with tick ``marks`` (band
    edges), for the panel (numbers) and the canvas (the bar)."""
    title: str
    lo: float
    hi: float
    colors: callable                     # values (N,) -> rgb (N, 3)
    marks: list = field(default_factory=list)
    unit: str = "strain"
    note: str = ""

    @property
    def text(self):
        fmt = self.fmt
        s = f"{self.title}: {fmt(self.lo)} .. {fmt(self.hi)}"
        if self.marks:
            s += " | band edges " + ", ".join(fmt(m) for m in self.marks)
        return s + (f" ({self.note})" if self.note else "")

    def ticks(self):
        """(position 0..1 along the bar, label) for the bar's two ends and each tick mark
        (band edge, zero) inside it, left to right: the labels written under the bar."""
        out = [(0.0, self.fmt(self.lo))]
        span = (self.hi - self.lo) or 1.0
        out += [((m - self.lo) / span, self.fmt(m) if m else "0") for m in sorted(self.marks)
                if 0.0 < (m - self.lo) / span < 1.0]
        return out + [(1.0, self.fmt(self.hi))]

    def place_ticks(self, width, measure=len, gap=1):
        """The tick labels placed on a line ``width`` units long (characters or pixels;
        ``measure(text)`` in the same units): [(start, text)], each centred under its tick
        and kept inside the line; the band edges first, then the ends where they do not
        overlap one already placed."""
        ticks = self.ticks()
        inner = ticks[1:-1]
        order = ([tk for tk in inner if tk[1] != "0"] + [ticks[0], ticks[-1]] +
                 [tk for tk in inner if tk[1] == "0"])
        placed = []
        for t, label in order:
            w = measure(label)
            start = min(max(t * width - w / 2, 0), width - w)
            if all(start + w + gap <= a or b + gap <= start for a, b, _ in placed):
                placed.append((start, start + w, label))
        return [(a, label) for a, _, label in sorted(placed)]

    def tick_line(self, n_chars):
        """The tick labels as one line of ``n_chars`` monospaced characters."""
        line = [" "] * n_chars
        for start, label in self.place_ticks(n_chars):
            k = int(round(start))
            line[k:k + len(label)] = label
        return "".join(line)[:n_chars].rstrip()

    def fmt(self, v):
        if self.unit == "strain":
            return f"{100 * v:+.2f}%"
        if self.unit == "mm":
            return f"{v:.1f} mm"
        return f"{v:.3g}"


def strain_bands(bands):
    """(warp, weft, bias) from a mapping with any of those keys (``Simulator.bands()``, or a
    ``strain`` settings section); a missing or empty bias band is the automatic one."""
    s = bands or {}
    warp = tuple(s.get("warp") or (-0.01, 0.01))
    weft = tuple(s.get("weft") or (-0.05, 0.05))
    bias = tuple(s["bias"]) if s.get("bias") else metrics.default_bias_band(warp, weft)
    return warp, weft, bias


def face_colors_legend(mode, x, uv, faces, grain, bands=None, rest_area=None,
                       strains=None):
    """Per-face RGB for a colour mode and its ``Legend`` (None for shading). Heat maps come
    from ``cloth.metrics`` (one definition); pass ``strains`` if already computed."""
    if mode == "shading":
        return np.tile(CLOTH_FRONT, (len(faces), 1)), None
    if mode not in COLOR_MODES:
        raise ValueError(f"unknown colour mode '{mode}': use one of {', '.join(COLOR_MODES)}")
    if mode == "size":
        area = metrics.material_areas(uv, faces) if rest_area is None else rest_area
        edge = 1e3 * np.sqrt(2.0 * np.asarray(area))      # mm: leg of a right triangle
        lo, hi = float(edge.min()), float(edge.max())
        if hi - lo < 1e-9:
            lo, hi = lo - 0.5, hi + 0.5
        colors = lambda v: _ramp((np.asarray(v) - lo) / (hi - lo), SEQ_SIZE)  # noqa: E731
        return colors(edge), Legend("triangle size (rest edge)", lo, hi, colors, unit="mm")
    if mode == "binding":
        # Which constraint binds (``strains["binding"]`` = (method, per-face index), from
        # ``ui.teaching.binding``); the key is drawn by the teaching layer, not a colour bar.
        method, idx = (strains or {}).get("binding", (None, None))
        return binding_colors(method, idx, len(faces))[0], None
    st = strains if strains is not None else metrics.face_strains(x, uv, faces, grain)
    warp, weft, bias = strain_bands(bands)
    if mode == "violation":
        # The violation of the method's own constraints (``strains["own"]``, per face, from
        # ``Simulator.own_violation``; None without a method), grey where it is within the
        # solver's tolerance ``strains["own_tol"]``: what strain limiting enforces, whatever
        # the method (the warp strain against its band is not, under svd or mapping).
        own = st.get("own")
        viol = np.zeros(len(faces)) if own is None else np.asarray(own, float)
        viol = np.where(viol <= st.get("own_tol", 0.0), 0.0, viol)
        scale = 0.01

        def colors(v):
            v = np.asarray(v, float)
            return np.where((v <= 0)[:, None], INSIDE, _ramp(v / scale, SEQ))
        return colors(viol), Legend("violation of the method's own limits", 0.0, scale, colors,
                                    note="grey: held" if own is not None else "no method")
    key, band, title = {
        "warp-strain": ("warp", warp, "warp strain"),
        "weft-strain": ("weft", weft, "weft strain"),
        "bias-strain": ("bias", bias, "bias strain"),
        "principal-strain": ("principal_max", (min(warp[0], weft[0]), max(warp[1], weft[1])),
                             "max principal strain"),
    }[mode]
    colors = lambda v: band_diverging(v, band)  # noqa: E731
    return colors(st[key]), Legend(title, 2 * min(band[0], -1e-6), 2 * max(band[1], 1e-6),
                                   colors, marks=[band[0], 0.0, band[1]])


def face_colors(mode, x, uv, faces, grain, bands=None, rest_area=None):
    """Per-face RGB for a colour mode and the legend as one line of text."""
    rgb, legend = face_colors_legend(mode, x, uv, faces, grain, bands, rest_area)
    return rgb, (legend.text if legend else "")


def binding_colors(method, idx, n_faces):
    """Per-face RGB of the binding map and its key: [(label, rgb, faces)] for the
    constraints that bind somewhere, then the free faces."""
    rgb = np.tile(FREE, (n_faces, 1))
    if idx is None or method not in metrics.CONSTRAINT_NAMES:
        return rgb, [("no strain limiting", FREE, n_faces)]
    names = metrics.CONSTRAINT_NAMES[method]
    key = []
    for k, name in enumerate(names):
        sel = idx == k
        rgb[sel] = BINDING_COLORS[name]
        if sel.any():
            key.append((name, np.array(BINDING_COLORS[name]), int(sel.sum())))
    key.append(("free (no limit binds)", FREE, int((idx < 0).sum())))
    return rgb, key
