"""Headless runs: simulate N frames and write the output folder.

    DIR/config.toml             the fully resolved configuration
    DIR/meshes/frame_NNNN.obj   v = positions, vt = material coordinates (frame 0 = initial)
    DIR/meshes/obstacles_NNNN.obj (or obstacles.obj when static)
    DIR/frames/frame_NNNN.png   GGUI offscreen, same drawing code as the window
    DIR/metrics.csv             one row per frame
    DIR/video.mp4               with --video

Files are written as frames finish, so a crash or a divergence keeps everything before it.
"""
import os
import sys

import numpy as np

from cloth import io
from cloth.simulator import SimulationDiverged

from .progress import Progress


class HeadlessRun:
    def __init__(self, sim, cfg, out_dir, images=True, video=False, color="shading",
                 meshes=True, every=1, size=(640, 480), quiet=False, overlays=()):
        from .overlays import TeachingLayer, frame_layout
        self.sim, self.cfg, self.out = sim, cfg, out_dir
        self.images, self.video, self.meshes = images or video, video, meshes
        self.color, self.every, self.size, self.quiet = color, max(1, int(every)), size, quiet
        # The teaching view (principal axes, strain-space plot, binding key), drawn into
        # every frame; the plot needs room, so a frame of the default size grows to 1280 x 720.
        self.teach = TeachingLayer(overlays)
        self.layout = frame_layout(self.teach.on)
        if "plot" in self.teach.on and tuple(size) == (640, 480):
            self.size = (1280, 720)
        self.renderer = None
        self._video_writer = None
        self.diverged = None
        self._faces = []

    # -- set-up -------------------------------------------------------------------------------
    def _prepare(self):
        # Everything that can fail at start-up comes first (the renderer needs a Vulkan
        # device), so a failed start leaves an earlier output folder as it was.
        if self.images:
            from .render import ClothRenderer, open_window
            window = open_window("Loom (offscreen)", self.size, show_window=False)
            self.renderer = ClothRenderer(window, self.sim.setup.camera)
            if "plot" in self.teach.on:
                r = self.renderer
                r.orbit.fit(self.sim.model.positions(), r.aspect, self.layout.view_x,
                            self.layout.view_y)
        from scenes.schema import commented_toml
        config_text = commented_toml(self.sim.settings.to_dict())
        os.makedirs(self.out, exist_ok=True)
        self._clear_earlier_output()
        if self.meshes:
            os.makedirs(os.path.join(self.out, "meshes"), exist_ok=True)
        if self.images:
            os.makedirs(os.path.join(self.out, "frames"), exist_ok=True)
        with open(os.path.join(self.out, "config.toml"), "w") as fh:
            fh.write("# Loom: the fully resolved configuration of this run\n")
            fh.write(config_text)
        if self.video:
            import imageio.v2 as imageio
            self._video_writer = imageio.get_writer(
                os.path.join(self.out, "video.mp4"), fps=self.cfg["sim"]["fps"],
                macro_block_size=8, quality=7)
        self.metrics = io.MetricsWriter(os.path.join(self.out, "metrics.csv"))
        self.sim.set_metrics_stage(True)     # its measuring is part of each frame's time

    def _clear_earlier_output(self):
        """Remove what an earlier run wrote here (only Loom's own file names), so the folder
        never mixes two runs' frames."""
        import glob
        patterns = ["config.toml", "metrics.csv", "video.mp4", "meshes/frame_*.obj",
                    "meshes/obstacles*.obj", "frames/frame_*.png"]
        for pat in patterns:
            for path in glob.glob(os.path.join(self.out, pat)):
                os.remove(path)

    # -- per frame ----------------------------------------------------------------------------
    def _write_frame(self):
        sim, f = self.sim, self.sim.frame
        self.metrics.write(sim.metrics_row())
        if f % self.every:
            return
        m = sim.model
        x = m.positions()
        if self.meshes:
            io.write_obj(os.path.join(self.out, "meshes", f"frame_{f:04d}.obj"), x, m.uv, m.faces)
            self._write_obstacles(f)
        if self.renderer is not None:
            from .render import draw_simulation
            draw_simulation(self.renderer, sim, self.color, teach=self.teach,
                            layout=self.layout)
            from .render import caption, frame_caption
            img = caption(self.renderer.image(), frame_caption(sim, os.path.basename(self.cfg.get("scene", ""))))
            if self.images:
                import imageio.v2 as imageio
                imageio.imwrite(os.path.join(self.out, "frames", f"frame_{f:04d}.png"), img)
            if self._video_writer is not None:
                self._video_writer.append_data(img)

    def _write_obstacles(self, f):
        obstacles = self.sim.setup.obstacles
        if not obstacles:
            return
        moving = any(getattr(o, "moving", False) for o in obstacles)
        name = f"obstacles_{f:04d}.obj" if moving else "obstacles.obj"
        path = os.path.join(self.out, "meshes", name)
        if not moving and os.path.exists(path):
            return
        verts, faces, off = [], [], 0
        for o in obstacles:
            v, fc = o.mesh_at(self.sim.time)
            verts.append(v)
            faces.append(np.asarray(fc) + off)
            off += len(v)
        io.write_plain_obj(path, np.concatenate(verts), np.concatenate(faces))

    # -- the run ------------------------------------------------------------------------------
    def _report_limit_miss(self, progress):
        """One line, the first time a frame ends above strain.tol (the count is in the final
        line: ``limit_summary``)."""
        sim = self.sim
        if sim.limit_misses == 1 and not getattr(self, "_miss_said", False):
            self._miss_said = True
            frame, value, rounds, budget = sim.first_limit_miss
            if progress:
                progress.end_line()
            print(f"loom: frame {frame} ended above the limits: own violation {value:.2g} > "
                  f"strain.tol {sim.settings.strain.tol:g} ({rounds} of {budget} AL rounds in "
                  "its last projection); later frames like it are counted, not printed",
                  file=sys.stderr, flush=True)

    def limit_summary(self):
        """'' or the run's count of frames that ended above strain.tol."""
        sim = self.sim
        if not sim.limit_misses:
            return ""
        worst, t = max((v, t) for t, v in sim.own_violation_log)
        return (f"{sim.limit_misses} frame(s) ended above strain.tol (largest own violation "
                f"{worst:.2g} at t = {t:.2f} s)")

    def remesh_summary(self):
        """'' without remeshing, else how often the run's mesh changed and its face counts:
        a remesh is computed every frame but applied only when it changes enough
        (``remesh.defer_ops``), so the frames remeshed are fewer than the frames run."""
        sim = self.sim
        if not sim.settings.remesh.enabled or not self._faces:
            return ""
        first, most, last = self._faces[0], max(self._faces), self._faces[-1]
        return (f"remeshed in {sim.remeshes_applied} of {sim.frame} frames (the others kept "
                f"their mesh: remesh.defer_ops); {first:,} faces at the start, {most:,} at "
                f"most, {last:,} at the end")

    def run(self, frames):
        """Simulate ``frames`` frames. Returns True if all ran; on divergence the folder keeps
        every frame before it and ``self.diverged`` holds the error."""
        self._prepare()
        progress = None if self.quiet else Progress(frames)
        frame_ms = []       # each frame's ms_total (metrics.csv): the progress line's median
        self._faces = [self.sim.model.n_faces]   # face count at the start and after each frame
        try:
            if progress:      # at once: the first frame may compile for a while
                progress.update(0, "first frame")
            self._write_frame()
            for k in range(frames):
                try:
                    self.sim.step_frame()
                except SimulationDiverged as err:
                    self.diverged = err
                    return False
                self._write_frame()
                self._report_limit_miss(progress)
                frame_ms.append(self.sim.frame_ms)
                self._faces.append(self.sim.model.n_faces)
                if progress:
                    progress.update(k + 1, f"simulation {np.median(frame_ms):.1f} ms a frame "
                                           "(median of metrics.csv ms_total)")
            return True
        finally:
            if progress:
                progress.close()
            self.metrics.close()
            if self._video_writer is not None:
                self._video_writer.close()
