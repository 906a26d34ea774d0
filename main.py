#!/usr/bin/env python3
"""Loom: strain-limited cloth simulation (Taichi).

    python main.py                      # the default scene; a window if there is a display
    python main.py hanging --headless --frames 60 --out out/hanging
    python main.py --list
    python main.py hanging --show-config
"""
import argparse
import contextlib
import os
import sys

# Exit codes (README): 0 the run finished and its final check held.
EXIT_BAD_INPUT = 2        # bad input, stopped before anything was computed or written
EXIT_DIVERGED = 3         # the state became non-finite; the output up to then is kept
EXIT_NO_RENDER = 4        # no Vulkan device for the window or the frames
EXIT_CHECK_FAILED = 5     # the run finished, but the scene's final check did not hold


def window_size(text):
    try:
        w, h = (int(t) for t in text.lower().replace("x", ",").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a window size: give W,H in pixels, "
                                         "e.g. 1280,720") from None
    if w < 320 or h < 240:
        raise argparse.ArgumentTypeError(f"window size {w}x{h} is too small: at least 320,240")
    return (w, h)


def band(text):
    try:
        lo, hi = (float(t) for t in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a band: give MIN,MAX as strains, "
                                         "e.g. -0.01,0.01") from None
    return [lo, hi]


class _HelpFormatter(argparse.HelpFormatter):
    """Shows a default only where there is one worth reading (not None, False or [])."""

    def _get_help_string(self, action):
        text = action.help or ""
        d = action.default
        if "%(default)" not in text and d not in (None, False, [], argparse.SUPPRESS) \
                and action.option_strings and action.nargs != 0:
            text += " (default: %(default)s)"
        return text


def parse_args(argv):
    p = argparse.ArgumentParser(
        prog="main.py", description="Loom: strain-limited cloth simulation. Without a display "
        "(or with --headless) it runs the scene and writes frames, meshes and metrics.",
        formatter_class=_HelpFormatter)
    p.add_argument("scene", nargs="?", default=None,
                   help="scene name (see --list) or a scene file, e.g. scenes/examples/drape.toml")
    p.add_argument("--list", action="store_true", help="list the scenes and fabrics and exit")
    p.add_argument("--fabric", metavar="NAME",
                   help="a measured fabric (fabrics/*.toml, see --list): its material and the "
                   "strain bands derived from its data (docs/fabrics.md); --set and the band "
                   "flags apply on top")
    p.add_argument("--show-config", action="store_true",
                   help="print every settable key of the scene with its value and exit")
    p.add_argument("--headless", action="store_true", help="no window: write files to --out")
    p.add_argument("--compare", action="store_true",
                   help="teaching view: the scene with the methods svd, warp-weft and mapping "
                   "side by side in one window (needs a display)")
    p.add_argument("--frames", type=int, help="frames to simulate, 1 or more (sim.frames)")
    p.add_argument("--out", help="output folder (default out/SCENE)")
    p.add_argument("--resolution", type=int, help="vertices along each side of a sheet "
                   "(cloth.resolution)")
    p.add_argument("--arch", default="cpu", metavar="ARCH",
                   help="Taichi backend to simulate on: cpu (any machine), gpu (the best GPU "
                   "backend available), cuda, vulkan or metal; one that cannot start stops with "
                   "a message")
    p.add_argument("--precision", default=None, choices=["f64", "f32"],
                   help="floating-point precision of the simulation (default f64; f32 on "
                        "vulkan and metal, which have no f64 kernels)")
    p.add_argument("--config", help="TOML file with settings (same keys as --show-config)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one setting, e.g. --set material.k_warp=50 (repeatable)")
    p.add_argument("--no-images", action="store_true", help="headless: skip PNG frames")
    p.add_argument("--video", action="store_true", help="headless: also write video.mp4")
    p.add_argument("--color", help="colour mode: shading, warp-strain, weft-strain, "
                   "bias-strain, principal-strain, violation, size, binding")
    p.add_argument("--window-size", type=window_size, metavar="W,H",
                   help="the window's size in pixels (default: 1280,800, shrunk to fit the "
                        "screen)")
    p.add_argument("--overlay", action="append", default=[], metavar="NAME[,NAME]",
                   help="teaching view, in the window and headless frames: 'axes' (principal "
                   "stretch directions over the warp/weft threads), 'plot' (every triangle in "
                   "strain space with the method's feasible box); with --color binding the "
                   "cloth shows which constraint binds")
    p.add_argument("--tour", action="store_true",
                   help="guided demo: the paper's experiment with svd, warp-weft and mapping "
                   "in turn, then mapping in a knit and a woven fabric, pausing at rest with the teaching view and a caption per step "
                   "(a window; headless: PNGs and video.mp4 in --out, default out/tour)")
    p.add_argument("--method", help="strain limiting: svd, warp-weft, mapping or none")
    p.add_argument("--warp", type=band, help="warp strain band MIN,MAX (paper: vertical)")
    p.add_argument("--weft", type=band, help="weft strain band MIN,MAX (paper: horizontal)")
    p.add_argument("--bias", type=band, help="bias strain band MIN,MAX (default: automatic)")
    p.add_argument("--solve", choices=("fast", "exact"),
                   help="how hard each strain projection is solved: fast (the default) or "
                        "exact (to its minimiser; slower)")
    p.add_argument("--rounds", type=int, help="strain limiting's AL round budget per projection")
    p.add_argument("--remesh", dest="remesh", action="store_true", default=None,
                   help="remesh every frame (overrides the scene)")
    p.add_argument("--no-remesh", dest="remesh", action="store_false",
                   help="never remesh (overrides the scene)")
    p.add_argument("--nudge", type=int, metavar="SEED",
                   help="start ~1 nm away at random (seed; sim.nudge): another run of a chaotic "
                        "scene, as another CPU gives")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p.parse_args(argv)


def flag_overrides(args, cfg_keys):
    """Command-line flags as a config override dict (only the flags given)."""
    ov = {}

    def put(section, key, value):
        if value is not None:
            ov.setdefault(section, {})[key] = value

    put("sim", "frames", args.frames)
    put("sim", "nudge", args.nudge)
    if args.resolution is not None:
        if "cloth" not in cfg_keys or "resolution" not in cfg_keys["cloth"]:
            raise ValueError("--resolution applies to sheet scenes only; this scene has no "
                             "cloth.resolution (see --show-config)")
        put("cloth", "resolution", args.resolution)
    put("output", "color", args.color)
    put("strain", "method", args.method)
    put("strain", "warp", args.warp)
    put("strain", "weft", args.weft)
    put("strain", "bias", args.bias)
    put("strain", "solve", args.solve)
    put("strain", "rounds", args.rounds)
    if args.remesh is not None:
        if "remesh" not in cfg_keys:
            raise ValueError("this scene has no remeshing settings")
        put("remesh", "enabled", args.remesh)
    if args.no_images:
        put("output", "images", False)
    if args.video:
        put("output", "video", True)
    return ov


def overlay_names(args):
    """The --overlay names, checked (comma-separated or repeated)."""
    from ui.overlays import OVERLAYS
    names = [n.strip() for item in args.overlay for n in item.split(",") if n.strip()]
    bad = [n for n in names if n not in OVERLAYS]
    if bad:
        raise ValueError(f"unknown overlay '{bad[0]}': use {' or '.join(OVERLAYS)} "
                         "(e.g. --overlay axes,plot)")
    return tuple(dict.fromkeys(names))


def has_display():
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _same_scene(a, b):
    """Two names of one scene (a built-in's name, or a scene file's path)."""
    return a == b or (os.path.exists(a) and os.path.exists(b) and os.path.samefile(a, b))


def fail(message, code=EXIT_BAD_INPUT):
    print(f"loom: error: {message}", file=sys.stderr)
    return code


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    # Taichi prints its version banner on import: to stderr, so that stdout carries only what
    # was asked for (--show-config's TOML, --list).
    with contextlib.redirect_stdout(sys.stderr):
        import taichi  # noqa: F401,F811
    try:
        overlays = overlay_names(args)
    except ValueError as err:
        return fail(str(err))
    if args.tour and (args.scene or args.compare):
        return fail("--tour runs its own scene (hanging, the three methods in turn): give no "
                    "scene and no --compare")
    if args.compare and not (args.list or args.show_config) and \
            (args.headless or not has_display()):
        # Said before Taichi starts: the simulator's first build compiles for a minute.
        return fail("--compare opens a window: run it on a desktop or under xvfb-run "
                    "(it has no headless mode)")
    if not (args.list or args.show_config):
        # Taichi starts before any scene or cloth module is imported: their module-level
        # types (``ti.types.matrix(3, 3, float)``, kernel argument types) take the float
        # type Taichi has when they are created, and before ti.init that is f32. Measured:
        # started after the imports, the window and the CLI ran the implicit step's matrix
        # (the strain projection's metric) and the obstacles' kernel arguments in f32 under
        # --precision f64, and the default drape landed elsewhere (lowest vertex 0.311 m at
        # frame 30 against 0.637 m in f64).
        from cloth import backend
        try:
            backend.init(args.arch, args.precision)
        except backend.BackendError as err:
            return fail(str(err))
        except Exception as err:  # Taichi could not start this arch (no driver, no device)
            return fail(f"Taichi could not start on --arch {args.arch} ({err}); use --arch cpu")
        for note in backend.start_notes():
            print(note, file=sys.stderr, flush=True)
    import scenes
    from cloth.config import ConfigError, load_toml, parse_assignment

    if args.list:
        for name in scenes.SCENES:
            print(f"{name:12s} {scenes.DESCRIPTIONS.get(name, '')}")
        examples = os.path.join(os.path.dirname(os.path.abspath(__file__)), "scenes", "examples")
        if os.path.isdir(examples):
            print("scene files (python main.py PATH):")
            for f in sorted(os.listdir(examples)):
                if f.endswith(".toml"):
                    print(f"  {os.path.relpath(os.path.join(examples, f))}")
        from cloth import fabrics
        print("\n".join(fabrics.list_lines()))
        return 0
    if args.tour and not (args.list or args.show_config):
        from ui.tour import run_tour
        return run_tour(args, headless=args.headless or not has_display())
    try:
        overrides = []
        config_scene = None
        if args.config:
            # A run's config.toml names its scene: with no scene given, it is the one run.
            config = load_toml(args.config)
            config_scene = config.pop("scene", None)
            if args.scene and config_scene and not _same_scene(args.scene, config_scene):
                raise ConfigError(f"{args.config} is the configuration of scene "
                                  f"'{config_scene}', not '{args.scene}': give no scene "
                                  "(python main.py --config FILE) or remove its scene line")
            overrides.append(config)
        name = args.scene or config_scene or scenes.DEFAULT_SCENE
        module = scenes.get(name)
        name = getattr(module, "NAME", name)      # a scene file: its file name without .toml
        if args.fabric:
            from cloth import fabrics
            overrides.append(fabrics.fabric_changes(args.fabric))
        overrides += [parse_assignment(s) for s in args.set]
        overrides.append(flag_overrides(args, module.DEFAULTS))
        from scenes.common import resolve
        cfg = resolve(module.DEFAULTS, overrides)
        cfg["scene"] = getattr(module, "path", name)
        if not cfg["sim"]["frames"] >= 1:
            raise ConfigError(f"sim.frames must be 1 or more (got {cfg['sim']['frames']}): "
                              "give --frames N with N >= 1")
        from cloth.settings import Settings
        from scenes.schema import show_config
        settings = Settings(cfg)   # ranges and choices (types and unknown keys: at the merge)
    except (KeyError, ConfigError, ValueError) as err:
        # KeyError's str() adds quotes around the message; the others are the message.
        return fail(err.args[0] if isinstance(err, KeyError) and err.args else str(err))
    if args.show_config:
        print(f"# settable keys of scene '{name}' (use --set KEY=VALUE or a TOML file; "
              "docs/scenes.md)")
        from cloth import fabrics
        for line in fabrics.annotate(show_config(cfg), cfg):
            print(line)
        return 0

    if hasattr(module, "check"):
        # Scene files: every input check (meshes, pins, obstacles) before the scene is built.
        try:
            module.check(cfg)
        except (ConfigError, ValueError) as err:
            return fail(str(err))

    headless = args.headless or not has_display()
    if headless and not args.headless:
        # Said before the simulator is built: building it may compile for minutes.
        print(f"loom: no display found, running '{name}' headless "
              "(use xvfb-run or a desktop for the window)", file=sys.stderr)
    from cloth.model import ModelError
    from cloth.simulator import Simulator
    try:
        setup = module.build(cfg)
        sim = Simulator(setup, settings)
    except (ModelError, ConfigError, ValueError) as err:
        return fail(str(err))

    if args.compare:
        from ui.render import RenderUnavailable
        try:
            from ui.app import run_compare
            return run_compare(cfg, module, overlays, size=args.window_size)
        except RenderUnavailable as err:
            return fail(f"{err}", EXIT_NO_RENDER)
    if not headless:
        from ui.render import RenderUnavailable
        try:
            from ui.app import run_app
            return run_app(sim, cfg, module, overlays, size=args.window_size)
        except RenderUnavailable as err:
            return fail(f"{err}; or use --headless", EXIT_NO_RENDER)
    return run_headless(sim, cfg, args, name, overlays)


def run_headless(sim, cfg, args, name, overlays=()):
    from ui.headless import HeadlessRun
    from ui.render import RenderUnavailable
    out = args.out or os.path.join("out", name)
    o = cfg["output"]
    run = HeadlessRun(sim, cfg, out, images=o["images"], video=o["video"], color=o["color"],
                      meshes=o["meshes"], every=o["every"], size=(o["width"], o["height"]),
                      quiet=args.quiet, overlays=overlays)
    from cloth.backend import LoopCapError
    try:
        ok = run.run(int(cfg["sim"]["frames"]))
    except RenderUnavailable as err:
        return fail(f"{err}", EXIT_NO_RENDER)
    except LoopCapError as err:     # a driver too limited for this mesh (Vulkan on lavapipe)
        return fail(f"{err}. Output up to frame {sim.frame} is in {out}/")
    if not ok:
        print(f"loom: {run.diverged}. Output up to frame {sim.frame} is in {out}/ "
              "(last good frame kept).", file=sys.stderr)
        return EXIT_DIVERGED
    ok_final, message = (True, "")
    if sim.setup.check_final is not None:
        ok_final, message = sim.setup.check_final(sim)
    misses = run.limit_summary()
    if misses:
        print(f"loom: {misses}", file=sys.stderr)
    remeshed = run.remesh_summary()
    if remeshed:
        print(f"loom: {remeshed}")
    print(f"loom: wrote {sim.frame} frames of '{name}' to {out}/ "
          f"(config.toml, metrics.csv, meshes/"
          + (", frames/" if o["images"] else "") + (", video.mp4" if o["video"] else "")
          + f"); final check: {'ok' if ok_final else 'FAILED'}"
          + (f" ({message})" if message else ""))
    return 0 if ok_final else EXIT_CHECK_FAILED


if __name__ == "__main__":
    sys.exit(main())
