"""The remesher's settings (``RemeshParams``), apart from the remesher itself so that the
settings schema (cloth/settings.py) can read their defaults without importing the mesh code
and Taichi."""
from dataclasses import dataclass


@dataclass
class RemeshParams:
    """Remeshing settings. Lengths in metres of material space.

    size_min, size_max: bounds on edge length the sizing field may ask for.
    aspect_min: smallest allowed ratio of short to long axis of the sizing ellipse (caps the
        anisotropy) and the lowest triangle quality (1 = equilateral in the metric) a collapse
        may create.
    refine_angle: rad, largest turning of the surface normal across one edge (curvature).
    refine_velocity: m/s, largest velocity difference across one edge.
    refine_compression: compressive strain at which a flat region is refined to ``size_min``
        (finer target length about ``size_min * sqrt(refine_compression / compression)``), so
        regions about to buckle are refined before the wrinkles form. Where the surface is
        already curved across the compression it asks for less, and nothing below a
        compression of about ``size_min * sqrt(refine_compression) * curvature``: a shell
        curved across the direction it is compressed in resists buckling (ARCSim's rib
        stiffening; 1.1 % on the drape's 0.3 m sphere). ``face_sizing_terms``.
    refine_obstacle, obstacle_reach: within ``obstacle_reach`` (m) of an obstacle, the largest
        change of the obstacle distance across an edge, as a fraction of the distance plus
        ``size_min``: refines where the cloth approaches or leaves an obstacle, not where it
        lies on it (the distance does not change along it). 1 and 0.05 m, as ARCSim (the
        change of height over the nearest obstacle's tangent plane at most the height, within
        10 repulsion thicknesses; Loom's collision thickness is 5 mm). With 0.25 and no reach
        (before), the drape's skirt was refined to ``size_min`` for several centimetres where
        it leaves the sphere (docs/remesh/drape.md).
    The terms are combined by the smallest metric that bounds each of them (``metric_max``),
    as ARCSim does, not by their sum: where two terms ask for the same size, the mesh has that
    size, not 0.7 of it.
    curvature_smoothing: rounds of face -> vertex -> face averaging of the signed shape operator
        before the curvature term squares it. Creases that zigzag one triangle wide (a
        strain-limited soft sheet crumples at the scale of its triangles) cancel, so refining
        does not find new ones at every size; a fold or a wrinkle a few triangles wide keeps
        its sign and survives. Measured (hanging, mapping, default sizes, faces at frame 10):
        0 rounds 6948 and still growing (5.7 s per frame), 1 round 3490, 2 rounds 2404
        (about 3k by frame 40, as many as hanging settles at without strain limiting).
    collapse_margin: hysteresis, so a just-split edge is not collapsed again next frame: a
        collapse may create edges up to ``1 - collapse_margin`` in metric length; an edge
        shorter than ``(1 - collapse_margin) / 2`` (it cannot be half of a recent split) may
        create edges up to 1, the split threshold (``_collapse_limit``). 0.1, as ARCSim's
        0.9: with 0.2 a mesh refined for a metric that then relaxes by 1.5 (a landing, then
        rest) stays at edges of 0.46 in it, since even a collapse to the midpoint makes edges
        of about 1.5-1.8 times the mesh's; with 0.1 it coarsens to 0.69 (4,608 against 2,665
        faces, tests/test_remesh.py).
    warm_multipliers: carry the strain solver's per-face multipliers to the faces a remesh
        makes (``face_data``, scaled by sqrt of the area ratio) so the projection after the
        remesh starts warm. Off: measured on hanging (docs/history/remesh_ops.md section 3, 30
        frames), the warm re-projection took 8 / 9.4 / 23 AL rounds (median / mean / max)
        against 6 / 6.4 / 8 from zero multipliers with mapping (8 / 8.9 / 14 against 5 / 5.2 /
        7 with warp-weft). That projection is the substep's second, on cloth already
        projected, so the substep's multipliers are the wrong start (as for the re-projection
        after collision_final). Warm multipliers do help warp-weft's next substep (16 against
        22 rounds); mapping's not (14 against 15).
    defer_ops, defer_frames: a remesh whose operations (splits + flips + collapses) are at most
        ``defer_ops`` times the face count is not applied (the simulator keeps the mesh it
        has), for at most ``defer_frames`` frames in a row; 0 applies every remesh. Why: what
        a new mesh sets off (the model's arrays, the bending matrix, the block pattern, a
        preconditioner that needs two solves on one pattern before it exists) costs the same
        for two flips as for two hundred, while a settling cloth asks for a handful of
        operations in most frames (docs/remesh/remesh_frame.md). Deferring them keeps the
        mesh, and everything built on it, for a few frames; the operations are not lost, the
        next remesh finds them again. Only the simulator reads these two (``remesh()`` always
        returns its whole result). It decides before making the remesh where it can: the
        edges to split and to flip are counted on the current mesh
        (``remesh.pending_operations``, a fraction of the remesh's cost) and, when they are
        at most ``defer_ops`` per face, the remesh is not made at all
        (``Simulator._defer_unmade``); a remesh it makes is deferred by its operations as
        before. Measured on hanging at resolution 46 (mapping, ~900 faces,
        median ms per frame over frames 10-60, single runs on a loaded machine): 0 54, 0.01
        44 (62 % of the remeshes applied), 0.05 32.
    """
    size_min: float = 0.015
    size_max: float = 0.08
    aspect_min: float = 0.2
    refine_angle: float = 0.3
    refine_velocity: float = 1.0
    refine_compression: float = 0.05
    refine_obstacle: float = 1.0
    obstacle_reach: float = 0.05
    curvature_smoothing: int = 2
    collapse_margin: float = 0.1
    collapse_rounds: int = 2
    warm_multipliers: bool = False
    defer_ops: float = 0.05
    defer_frames: int = 4

    def validate(self):
        if not self.size_min > 0:
            raise _error()(f"remesh size_min must be > 0 m (got {self.size_min}); "
                             "e.g. 0.015 for a 1 m cloth")
        if not self.size_max >= self.size_min:
            raise _error()(f"remesh size_max ({self.size_max}) must be >= size_min "
                             f"({self.size_min}); raise size_max or lower size_min")
        if not 0 < self.aspect_min <= 1:
            raise _error()(f"remesh aspect_min must be in (0, 1] (got {self.aspect_min}); "
                             "0.2 allows 5:1 anisotropic triangles")
        for name in ("refine_angle", "refine_velocity", "refine_compression",
                     "refine_obstacle"):
            if not getattr(self, name) > 0:
                raise _error()(f"remesh {name} must be > 0 (got {getattr(self, name)}); "
                                 "a larger value refines less")
        if not self.obstacle_reach > 0:
            raise _error()(f"remesh obstacle_reach must be > 0 m (got {self.obstacle_reach}); "
                             "0.05 refines within 5 cm of an obstacle")
        if not 0 <= self.collapse_margin < 1:
            raise _error()(f"remesh collapse_margin must be in [0, 1) (got "
                             f"{self.collapse_margin}); 0.2 is a good hysteresis")
        if not (isinstance(self.curvature_smoothing, int) and self.curvature_smoothing >= 0):
            raise _error()(f"remesh curvature_smoothing must be a whole number >= 0 (got "
                             f"{self.curvature_smoothing}); 0 uses each face's own curvature")
        if not self.collapse_rounds >= 0:
            raise _error()("remesh collapse_rounds must be >= 0")
        if not (self.defer_ops >= 0 and isinstance(self.defer_frames, int)
                and self.defer_frames >= 0):
            raise _error()(f"remesh defer_ops must be >= 0 and defer_frames a whole number "
                             f">= 0 (got {self.defer_ops}, {self.defer_frames}); 0 applies "
                             "every remesh")


def _error():
    from .model import ModelError      # the mesh code's error; imported only when raised
    return ModelError
