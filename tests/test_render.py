"""Headless frames come from GGUI offscreen (the window's drawing code)."""
import numpy as np
import pytest

from ui.colormap import face_colors
from ui.render import RenderUnavailable


@pytest.fixture(scope="module")
def renderer():
    from ui.render import ClothRenderer, open_window
    try:
        window = open_window("test", (320, 240), show_window=False)
    except RenderUnavailable as err:
        pytest.skip(f"no Vulkan device: {err}")
    return ClothRenderer(window, {"position": [0, 1.5, 2.6], "lookat": [0, 1.45, 0]})


def test_offscreen_frame_shows_the_cloth(renderer):
    from tests.test_scenes import make_sim
    from ui.render import draw_simulation
    sim, _ = make_sim(cloth={"resolution": 7}, strain={"method": "none"})
    for _ in range(3):
        sim.step_frame()
    draw_simulation(renderer, sim, "shading")
    img = renderer.image().astype(float) / 255
    assert img.shape == (240, 320, 3)
    # The cloth covers the middle of the picture and is lit (orange-ish, not background grey).
    centre = img[80:160, 120:200]
    orange = (centre[..., 0] > centre[..., 2] + 0.15)
    assert orange.mean() > 0.8
    assert img[5:20, 5:20].std() < 0.02          # plain background in the corner


def test_the_cloth_shows_whatever_the_drivers_transform_buffer_held(renderer):
    """GGUI's mesh shader multiplies an instance transform by 0 when a mesh has none, and a
    plain mesh call never writes that buffer: NaN left in it (lavapipe's memory comes from
    the process's heap) hid the cloth, depending on what ran before (ui/ggui_buffers.py).
    Here NaN is written into it on purpose; the next frame still shows the cloth, because
    every mesh draw now writes its identity transform into that same buffer. (The plain call
    lost the cloth here only when the driver's next allocation reused the NaN memory.)"""
    from taichi.ui.utils import get_field_info
    from tests.test_scenes import make_sim
    from ui.render import draw_simulation
    sim, _ = make_sim(cloth={"resolution": 7}, strain={"method": "none"})
    sim.step_frame()

    def orange_share():
        img = renderer.image().astype(float) / 255
        return (img[..., 0] > img[..., 2] + 0.15).mean()
    draw_simulation(renderer, sim, "shading")
    shown = orange_share()
    assert shown > 0.05
    renderer.begin()                    # the same mesh renderable, with NaN transforms
    vbo = np.zeros((3, 12), np.float32)
    nan = np.full((1, 4, 4), np.nan, np.float32)
    renderer.scene.scene.mesh_instance(get_field_info(vbo), True, get_field_info(None),
                                       (0.5, 0.5, 0.5), True, get_field_info(nan), 1, 0, 3, 0,
                                       3, 0, False)
    renderer.finish()
    renderer.image()
    draw_simulation(renderer, sim, "shading")
    assert orange_share() == shown
    calls = []                          # each mesh: one instance, the identity

    class Scene:
        def mesh_instance(self, *args):
            calls.append(args)
    from ui.ggui_buffers import VertexBuffers, draw_mesh
    draw_mesh(type("S", (), {"scene": Scene()})(), VertexBuffers(), "m", np.zeros((3, 3)),
              np.zeros((3, 3)), np.ones((3, 3)))
    transforms = calls[0][5]
    assert transforms.valid and tuple(transforms.shape) == (1, 4, 4) and calls[0][6] == 1
    from ui.ggui_buffers import IDENTITY
    assert np.array_equal(IDENTITY[0], np.eye(4))


def test_strain_colour_modes_come_from_metrics():
    from cloth.sheet import make_sheet
    uv, faces = make_sheet(1, 1, 4, 4)
    x = np.c_[uv[:, 0] * 1.05, uv[:, 1] * 0.98, np.zeros(len(uv))]   # 5 % warp, -2 % weft
    grain = np.tile(np.eye(2), (len(faces), 1, 1))
    warp, _ = face_colors("warp-strain", x, uv, faces, grain, {"warp": [-0.05, 0.05]})
    weft, _ = face_colors("weft-strain", x, uv, faces, grain, {"weft": [-0.05, 0.05]})
    assert np.all(warp[:, 0] > warp[:, 2])      # stretched: red
    assert np.all(weft[:, 2] > weft[:, 0])      # compressed: blue


def test_headless_frames_say_what_they_show(renderer, tmp_path, monkeypatch):
    """Each written frame carries a caption (scene, frame, time, method, bands) on a strip
    along its top; the colour bar's band edges are written under their ticks. (The run draws
    into this module's offscreen window: a second GGUI window in one process crashes.)"""
    import imageio.v2 as imageio
    import ui.render
    from tests.test_scenes import make_sim
    from ui.colormap import Legend
    from ui.headless import HeadlessRun
    from ui.render import frame_caption
    sim, cfg = make_sim(cloth={"resolution": 7}, strain={"method": "warp-weft"})
    cfg["scene"] = "hanging"
    monkeypatch.setattr(ui.render, "open_window", lambda *a, **k: renderer.window)
    run = HeadlessRun(sim, cfg, str(tmp_path), color="warp-strain", quiet=True, size=(320, 240))
    assert run.run(2)
    text = frame_caption(sim, "hanging")
    assert text.startswith("hanging   frame 2   t = 0.07 s   warp-weft   warp -1..+1 %")
    img = imageio.imread(tmp_path / "frames" / "frame_0002.png").astype(int)
    strip, below = img[:15, :300], img[25:60, :300]
    assert (strip.sum(axis=2) < 300).sum() > 100            # dark text on the strip
    assert (below.sum(axis=2) < 300).sum() == 0             # the background below it
    lg = Legend("warp strain", -0.02, 0.02, None, marks=[-0.01, 0.0, 0.01])
    placed = dict((label, start) for start, label in lg.place_ticks(300, lambda t: 6 * len(t)))
    assert abs(placed["-1.00%"] + 18 - 75) < 1 and abs(placed["+1.00%"] + 18 - 225) < 1
    assert abs(placed["0"] + 3 - 150) < 1
