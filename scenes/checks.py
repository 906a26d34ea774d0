"""The pieces of the scenes' final checks (``check_final(sim) -> (ok, message)``).

Each piece takes what it reads (a simulator, positions, geometry from the scene's settings)
and returns ``(ok, text)``: when it fails, ``text`` is the one-line reason; when it holds, a
short statement of what was found (or "" when there is nothing worth saying). ``combine``
runs pieces in order and stops at the first failure, so a non-finite state is reported as
such and not as a violated limit.

A check tests what its scene is for, and tests/test_final_checks.py builds a plainly wrong
state for each piece (a flat sheet on the sphere's top, an open seam, a sheet stretched past
its band, a moving sheet) and shows that it fails.
"""
import numpy as np

# Own-constraint violation accepted at the end of a frame, in units of strain.tol: each solve
# ends below tol, and the obstacle pass after it may move a vertex a little (the smoke runs of
# every scene stay under 2 tol, tests/test_all_scenes.py).
LIMIT_FACTOR = 2.0
# At rest: mass-weighted RMS speed below this (m/s). The solver's rest targets for the hanging
# sheet (kinetic energy 3e-7 to 1e-6 J, 0.15 kg) are 2.0-3.7 mm/s; it rests at 0.5 mm/s
# (mapping, resolution 25, 5 s); a swinging sheet moves at 0.1-1 m/s.
REST_SPEED = 0.004


def before(sim, t):
    """The run has not reached ``t`` seconds yet. (Time is a sum of substeps: after 150
    frames at 30 fps it reads 4.9999999999999 s, which counts as 5 s.)"""
    return sim.time < t - 1e-6


def combine(*pieces):
    """Run the pieces (callables returning (ok, text)) in order: the first failure, or
    (True, the passing texts joined)."""
    notes = []
    for piece in pieces:
        ok, text = piece()
        if not ok:
            return False, text
        if text:
            notes.append(text)
    return True, ", ".join(notes)


def finite(sim):
    x = sim.model.positions()
    v = sim.model.velocities()
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(v))):
        return False, "non-finite state"
    return True, ""


def seconds(t):
    """A time for a check's line: at most two decimals, no trailing zeros (5, 0.5, 0.76)."""
    return f"{t:.2f}".rstrip("0").rstrip(".")


def limits_held(sim, factor=LIMIT_FACTOR, after=0.0):
    """The current method's own constraints held to ``factor`` x strain.tol now and at the end
    of every frame from ``after`` seconds on (the simulator's watch, ``own_violation_log``;
    a scene whose cloth lands on an obstacle gives its landing time: an impact can leave a
    frame or two beyond the limits). Nothing to check without a method."""
    own = sim.own_violation()
    if own is None:
        return True, ""
    if before(sim, after):
        return True, f"limits not checked before {seconds(after)} s"
    worst, at = (float(own.max()) if own.size else 0.0), sim.time
    for t, value in sim.own_violation_log:
        if t >= after - 1e-6 and value > worst:
            worst, at = value, t
    limit = factor * sim.settings.strain.tol
    since = f" from {seconds(after)} s" if after > 0 else ""
    if not worst <= limit:
        return False, (f"the {sim.method} limits are not held: own violation {worst:.2g} > "
                       f"{limit:.2g} (strain) at t = {at:.2f} s")
    return True, f"{sim.method} limits held{since} (largest own violation {worst:.1e})"


def rms_speed(sim):
    """Mass-weighted RMS speed of the cloth (m/s)."""
    v, m = sim.model.velocities(), sim.model.mass
    return float(np.sqrt(np.sum(m * np.einsum("ij,ij->i", v, v)) / max(np.sum(m), 1e-300)))


def at_rest(sim, after, speed=REST_SPEED):
    """From ``after`` seconds on, the cloth is at rest (RMS speed under ``speed``)."""
    if before(sim, after):
        return True, f"rest not checked before {seconds(after)} s"
    s = rms_speed(sim)
    if not s < speed:
        return False, (f"not at rest after {sim.time:.1f} s: RMS speed {1e3 * s:.1f} mm/s "
                       f"(at rest: under {1e3 * speed:.0f} mm/s)")
    return True, f"at rest ({1e3 * s:.2f} mm/s)"


def seams_closed(sim, gap_max, after=0.0):
    """From ``after`` seconds on, every stitch pair lies within ``gap_max`` metres."""
    st = np.asarray(sim.dynamics.stitches_np).reshape(-1, 2)
    if not len(st) or before(sim, after):
        return True, ""
    x = sim.model.positions()
    gap = float(np.linalg.norm(x[st[:, 0]] - x[st[:, 1]], axis=1).max())
    if not gap <= gap_max:
        return False, f"a seam is {gap:.4f} m open (closed: within {gap_max:g} m)"
    return True, f"seams closed ({1e3 * gap:.2g} mm)"


def outside(depth, tol, what):
    """``depth``: signed distances of the vertices to a body (negative inside)."""
    worst = -float(np.min(depth))
    if worst > tol:
        return False, f"a vertex is {worst:.4f} m inside {what}"
    return True, ""


def drape_time(start_height, center, radius, gravity):
    """When a cloth dropped from ``start_height`` (m, its lowest point) onto a sphere must
    hang draped (s): twice the free-fall time down to the sphere's lowest point."""
    fall = max(float(start_height) - (float(center[1]) - float(radius)), 0.0)
    return 2.0 * float(np.sqrt(2.0 * fall / float(np.linalg.norm(gravity))))


FOLD_SIDES = 2           # of 8: the sides where a fold may rest above the equator


def draped_over_sphere(x, center, radius, margin, sectors=8):
    """The cloth hangs over a sphere: some of it rests on the sphere's top (within ``margin``
    of the surface, within 30 degrees of the pole), it reaches below the equator, and on every
    side where it lies outside the sphere's outline seen from above (further than ``margin``
    from the vertical axis beyond the radius), its lowest point there is below the equator,
    on all but ``FOLD_SIDES`` of them: a landing is chaotic, and a fold may come to rest on
    the top (measured on the drape scene over 115 starts 1 nm apart: 6 ended with folds up
    to 2.5 cm above the equator on one or two sides, the rest hanging). A flat sheet lying
    on the top fails on every side, one flat on half of it on four; a sheet beside the
    sphere fails the first test."""
    c = np.asarray(center, float)
    rel = np.asarray(x, float) - c
    dist = np.linalg.norm(rel, axis=1) - radius
    on_top = (dist < margin) & (rel[:, 1] > radius * np.cos(np.radians(30.0)))
    if not on_top.any():
        return False, "no cloth rests on the sphere's top (it slid off or never landed)"
    if not rel[:, 1].min() < 0.0:
        return False, (f"not draped: the cloth's lowest point is {rel[:, 1].min():.3f} m above "
                       "the sphere's equator")
    rho = np.hypot(rel[:, 0], rel[:, 2])
    beyond = rho > radius + margin
    angle = np.arctan2(rel[beyond, 2], rel[beyond, 0])
    side = np.minimum((sectors * (angle + np.pi) / (2 * np.pi)).astype(int), sectors - 1)
    lowest = np.full(sectors, np.inf)
    np.minimum.at(lowest, side, rel[beyond, 1])
    seen = np.isfinite(lowest)
    flat = seen & (lowest >= 0.0)
    if flat.sum() > FOLD_SIDES:
        worst = int(np.argmax(np.where(flat, lowest, -np.inf)))
        return False, (f"not draped: on {flat.sum()} of the {seen.sum()} sides where the cloth "
                       f"reaches past the sphere it stays above the equator (up to "
                       f"{lowest[worst]:.3f} m above it, towards "
                       f"{np.degrees(-np.pi + (worst + 0.5) * 2 * np.pi / sectors):.0f} deg "
                       "from x): it lies on the sphere's top")
    if not seen.any():
        return True, "draped over the sphere (wrapped round it below its equator)"
    if flat.any():
        return True, (f"draped over the sphere (below its equator on {seen.sum() - flat.sum()} "
                      f"of {seen.sum()} sides; on the others folds rest up to "
                      f"{lowest[flat].max():.3f} m above it)")
    if not seen.all():
        return True, (f"draped over the sphere (below its equator on the {seen.sum()} of "
                      f"{sectors} sides where it reaches past the sphere)")
    return True, f"draped over the sphere (below its equator on all {sectors} sides)"
