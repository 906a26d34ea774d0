"""The command line: clear one-line errors for bad input, and the headless output folder."""
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def run_main(*args, cwd=None):
    env = dict(os.environ)
    env.pop("DISPLAY", None)
    env.pop("WAYLAND_DISPLAY", None)
    return subprocess.run([sys.executable, os.path.join(ROOT, "main.py"), *args],
                          capture_output=True, text=True, cwd=cwd or ROOT, env=env, timeout=600)


def run_main_here(*args):
    """``main.main(args)`` in this test process, reported like ``run_main`` (returncode,
    stdout, stderr), without a display. The strain solver's kernels, compiled once per process
    (ndarray arguments), are then reused from earlier tests; a subprocess compiles them again
    (10-20 s each on 2 cores), and a child process's start alone costs ~1.5 s (Python and
    Taichi). Use ``run_main`` where the entry point itself is under test (the exit code
    through ``sys.exit``, argparse's own ``--help``)."""
    import contextlib
    import io
    from types import SimpleNamespace
    import main as loom_main
    out, err = io.StringIO(), io.StringIO()
    saved = {k: os.environ.pop(k) for k in ("DISPLAY", "WAYLAND_DISPLAY") if k in os.environ}
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            code = loom_main.main([str(a) for a in args])
    finally:
        os.environ.update(saved)
    return SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


def assert_clear_error(res, *words):
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr
    lines = [ln for ln in res.stderr.splitlines() if ln.startswith("loom: error:")]
    assert len(lines) == 1, res.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_unknown_scene():
    assert_clear_error(run_main("hangin", "--headless"), "unknown scene", "did you mean 'hanging'")


def test_compare_without_a_window_is_refused_before_taichi_starts(monkeypatch):
    """--compare has no headless mode: without a display (or with --headless) it says so in
    one line and names the fix, before Taichi starts (a first build compiles for a minute)."""
    from cloth import backend
    started = []
    monkeypatch.setattr(backend, "init", lambda *a, **k: started.append(a))
    for args in (("hanging", "--compare"), ("--compare", "--headless")):
        assert_clear_error(run_main_here(*args), "--compare opens a window", "xvfb-run")
    assert started == []


def test_f64_on_vulkan_is_refused_with_the_fix(tmp_path):
    """Taichi's SPIR-V back ends have no f64 kernels: asking for them names --precision f32
    (exit 2, nothing written) instead of failing inside a kernel compile; without --precision
    Vulkan and Metal default to f32. Checked before Taichi starts, so no Vulkan is needed."""
    from cloth import backend
    assert backend.default_precision("vulkan") == "f32"
    assert backend.default_precision("metal") == "f32"
    assert backend.default_precision("cpu") == "f64"
    with pytest.raises(backend.BackendError, match="--precision f32"):
        backend.init("vulkan", "f64")
    assert backend.arch() == "cpu"             # the running backend is untouched
    out = tmp_path / "out"
    r = run_main_here("hanging", "--headless", "--arch", "vulkan", "--precision", "f64",
                      "--frames", "1", "--out", str(out))
    assert r.returncode == 2 and "--precision f32" in r.stderr
    assert not out.exists()


def test_unknown_set_key():
    assert_clear_error(run_main_here("hanging", "--set", "material.k_wrap=3", "--headless"),
                       "unknown setting 'material.k_wrap'", "k_warp")


def test_malformed_toml(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[material\nk_warp = 3\n")
    assert_clear_error(run_main_here("hanging", "--config", str(bad), "--headless"),
                       "not valid TOML")


@pytest.mark.parametrize("setting", ["sim.fps=-30", "sim.fps=0", "sim.substeps=0"])
def test_non_positive_time_step(setting):
    # Refused by the schema (scenes/schema.py) before anything is built.
    key = setting.split("=")[0]
    assert_clear_error(run_main_here("hanging", "--set", setting, "--headless", "--frames", "1"),
                       key, "must be", f"--set {key}=")


def test_degenerate_material_triangles():
    # A zero-width sheet is refused by the schema; degenerate triangles of a mesh file are
    # refused when it is loaded (tests/test_scene_files.py).
    assert_clear_error(run_main_here("hanging", "--set", "cloth.width=0", "--headless",
                                     "--frames", "1"),
                       "cloth.width", "must be > 0 m")


def test_list_and_show_config():
    res = run_main_here("--list")
    assert res.returncode == 0 and "hanging" in res.stdout
    res = run_main_here("hanging", "--show-config", "--set", "material.preset=\"cotton\"")
    assert res.returncode == 0
    assert "material.k_warp = 3000.0" in res.stdout and "cloth.resolution = 25" in res.stdout


@pytest.fixture(scope="module")
def headless_run(tmp_path_factory):
    """One command-line run for the tests below (a child process compiles its kernels on
    its own: 7-30 s): hanging, 3 frames at resolution 6, the documented folder in ``out``."""
    out = tmp_path_factory.mktemp("cli") / "run"
    res = run_main("hanging", "--headless", "--frames", "3", "--resolution", "6", "--out", str(out),
                   "--no-images", "--quiet")
    return res, out


@pytest.mark.xdist_group("cli_run")     # one worker: the command-line run happens once
@pytest.mark.no_jitter     # the child process's run is not moved: the library's must not be
def test_the_command_line_simulates_in_f64_like_the_library(headless_run):
    """``main.py`` starts Taichi before it imports the scenes, so the module-level Taichi
    types (the implicit step's block matrix, the obstacles' kernel arguments) are f64 under
    the default precision. Started after the imports they were f32, and the CLI's frames
    drifted from the library's. Here the CLI's frame 3 matches an in-process f64 run to the
    OBJ's 9 digits."""
    res, out = headless_run
    assert res.returncode == 0, res.stderr
    with open(out / "meshes" / "frame_0003.obj") as fh:
        cli = np.array([[float(t) for t in line.split()[1:4]] for line in fh
                        if line.startswith("v ")])
    import scenes
    from cloth.simulator import Simulator
    from scenes.common import resolve
    mod = scenes.get("hanging")
    cfg = resolve(mod.DEFAULTS, [{"cloth": {"resolution": 6}}])
    assert cfg["strain"]["method"] != "none"         # the strain solve runs in both
    sim = Simulator(mod.build(cfg), cfg)
    for _ in range(3):
        sim.step_frame()
    assert np.abs(cli - sim.model.positions()).max() < 1e-7


@pytest.mark.xdist_group("cli_run")     # one worker: the command-line run happens once
def test_headless_writes_the_documented_folder(headless_run):
    import trimesh
    res, out = headless_run
    assert res.returncode == 0, res.stderr
    assert str(out) in res.stdout
    assert (out / "config.toml").exists()
    import tomllib
    cfg = tomllib.loads((out / "config.toml").read_text())
    assert cfg["cloth"]["resolution"] == 6 and cfg["sim"]["frames"] == 3
    rows = (out / "metrics.csv").read_text().splitlines()
    header = rows[0].split(",")
    for col in ["frame", "time", "vertices", "faces", "ms_total", "ms_dynamics", "kinetic_energy",
                "warp_strain_max", "warp_strain_rms", "weft_strain_max", "weft_strain_rms", "nan",
                "cg_iterations", "cg_preconditioner"]:
        assert col in header
    assert len(rows) == 1 + 4
    last = dict(zip(header, rows[-1].split(",")))
    assert last["cg_preconditioner"] in ("block Jacobi", "factor", "multigrid")
    for f in range(4):
        path = out / "meshes" / f"frame_{f:04d}.obj"
        mesh = trimesh.load(str(path), process=False, maintain_order=True)
        assert len(mesh.vertices) == 36 and len(mesh.faces) == 50
    # vt holds the material coordinates (metres): the hanging sheet is 1 m x 1 m.
    from cloth.io import read_obj_uv
    from cloth.sheet import make_sheet
    x, uv, faces = read_obj_uv(str(out / "meshes" / "frame_0003.obj"))
    uv_ref, faces_ref = make_sheet(1.0, 1.0, 6, 6, "alternating")
    assert np.allclose(uv, uv_ref, atol=1e-12) and np.array_equal(faces, faces_ref)
    assert np.allclose(mesh.visual.uv, uv_ref, atol=1e-9)


@pytest.mark.parametrize("frames", ["-3", "0"])
def test_non_positive_frame_count_is_refused_and_nothing_written(frames, tmp_path):
    out = tmp_path / "run"
    res = run_main_here("hanging", "--headless", "--frames", frames, "--out", str(out))
    assert_clear_error(res, "sim.frames must be 1 or more", "--frames N")
    assert not out.exists()
    assert "final check" not in res.stdout


def test_help_describes_every_option():
    res = run_main("--help")
    assert res.returncode == 0
    text = " ".join(res.stdout.split())
    assert "--arch ARCH Taichi backend to simulate on: cpu" in text
    assert "(default: None)" not in text and "(default: False)" not in text
