"""Write the cloth meshes of the example scene files: ``python -m scenes.examples.make_examples``.

The four built-in scenes as files (``hanging.toml``, ``pull.toml``, ``drape.toml``,
``tshirt.toml``) use meshes written here from the built-in builders at their default settings,
with every number printed exactly (17 significant digits), so that a file scene starts from the
same state as its built-in scene (tests/test_scene_files.py compares the first frames):

  hanging.obj, pull.obj, drape.obj   the sheets (v = start positions, vt = material coordinates)
  tshirt.obj                         the two T-shirt panels (panels apart, as in assets/)
  tshirt_stitches.txt                its seam pairs, 1-based OBJ vertex indices

The garment example (``garment.toml``) uses ``assets/garment.obj``, made by
``python -m assets.make_assets --garment``.
"""
import os

import numpy as np

from cloth.garment import write_garment_obj

HERE = os.path.dirname(os.path.abspath(__file__))


def write_exact_obj(path, x, uv, faces, header):
    """A mesh whose v and vt share their numbering, with coordinates that round-trip exactly."""
    faces = np.asarray(faces, np.int64)
    write_garment_obj(path, x, uv, np.stack([faces, faces], axis=2), header=header, digits=17)


def main():
    from cloth import backend
    backend.init("cpu", "f64")
    import scenes
    from scenes.common import resolve
    for name in ("hanging", "pull", "drape"):
        module = scenes.get(name)
        cfg = resolve(module.DEFAULTS, [])
        m = module.build(cfg).mesh
        path = os.path.join(HERE, f"{name}.obj")
        write_exact_obj(path, m.x, m.uv, m.faces,
                        f"Loom example: the '{name}' scene's sheet at its default settings\n"
                        "v = start position (m), vt = material coordinate (m)\n"
                        "made by python -m scenes.examples.make_examples")
        print(f"wrote {path}")
    from assets import load_tshirt
    d = load_tshirt()
    path = os.path.join(HERE, "tshirt.obj")
    write_exact_obj(path, d["x"], d["uv"], d["faces"],
                    "Loom example: the T-shirt of assets/tshirt.npz (front and back panel)\n"
                    "v = start position (m), vt = material coordinate (m), warp = material v\n"
                    "made by python -m scenes.examples.make_examples")
    path_st = os.path.join(HERE, "tshirt_stitches.txt")
    np.savetxt(path_st, np.asarray(d["stitches"], np.int64) + 1, fmt="%d %d",
               header="T-shirt seams: pairs of 1-based vertex indices of tshirt.obj to sew")
    print(f"wrote {path} and {path_st}")


if __name__ == "__main__":
    main()
