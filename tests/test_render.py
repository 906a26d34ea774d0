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


def test_strain_colour_modes_come_from_metrics():
    from cloth.sheet import make_sheet
    uv, faces = make_sheet(1, 1, 4, 4)
    x = np.c_[uv[:, 0] * 1.05, uv[:, 1] * 0.98, np.zeros(len(uv))]   # 5 % warp, -2 % weft
    grain = np.tile(np.eye(2), (len(faces), 1, 1))
    warp, _ = face_colors("warp-strain", x, uv, faces, grain, {"warp": [-0.05, 0.05]})
    weft, _ = face_colors("weft-strain", x, uv, faces, grain, {"weft": [-0.05, 0.05]})
    assert np.all(warp[:, 0] > warp[:, 2])      # stretched: red
    assert np.all(weft[:, 2] > weft[:, 0])      # compressed: blue
