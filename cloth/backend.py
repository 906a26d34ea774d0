"""Taichi start-up in one place: architecture and floating-point precision.

Taichi fixes the default float type at ``ti.init``; every field and kernel in ``cloth`` uses
``float`` (Taichi's default float), so one call here decides f32 or f64 for the whole run.
"""
import taichi as ti

ARCHES = {"cpu": "cpu", "gpu": "gpu", "cuda": "cuda", "vulkan": "vulkan", "metal": "metal"}
PRECISIONS = ("f64", "f32")
# Taichi's SPIR-V back ends (Vulkan, Metal) have no 64-bit float math (the strain kernels' atan2
# fails to compile: "the operand type of instruction Atan2 must <= 32bits"), so they run in f32.
F32_ONLY = ("vulkan", "metal")
# Back ends where the one-launch AL solve (strain/al.py solve_al: one serial thread
# running the whole projection) is not used. Measured on lavapipe (Debian's software Vulkan):
# it crashes the process (segmentation fault at the next read-back); the Cholesky path, whose
# loop runs on the host between small kernels, runs (hanging, resolution 9, 5 frames). Metal
# (Taichi's other SPIR-V back end) was not available to test and is treated the same way.
HOST_LOOP_AL = ("vulkan", "metal")

# Back ends on which Loom's serial launches (a whole solve in one kernel thread: ``for _ in
# range(1)`` under ``serialize=True``) run on a single GPU thread; said once at start-up
# (``start_notes``; docs/speed/gpu_plan.md: what a parallel version would need and give).
ONE_GPU_THREAD = ("cuda", "amdgpu")

_state = {"arch": None, "precision": None, "fast": None, "requested": None}
_gpu = {"resolved": None}


class BackendError(RuntimeError):
    """Raised when Taichi cannot start with the requested settings."""


class LoopCapError(RuntimeError):
    """A serial kernel's loops were cut short by the driver: Mesa's llvmpipe (Debian's
    software Vulkan, lavapipe) runs at most 65535 loop iterations in one shader invocation and
    then ends every loop without an error (cloth/strain/direct.py ``LOOP_CAP``). Raised by the
    launches that probe for it (``loop_probe``)."""


# The most loop iterations lavapipe runs in one shader invocation (cloth/strain/direct.py).
LOOP_CAP = 65535


@ti.func
def loop_probe(two):
    """2 when a loop of ``two`` (= 2, a run-time value: a constant count is unrolled and
    escapes the cap) iterations runs in full, 1 once the driver's loop cap was hit in this
    launch (llvmpipe then runs a loop's body once). Serial kernels end with it."""
    n = 0
    for _ in range(two):
        n += 1
    return n


def check_loop_probe(ran, kernel, mesh, largest):
    """Raise LoopCapError, naming the fix, unless a launch's ``loop_probe`` returned 2.
    ``kernel``: what was cut short; ``mesh``: its size in words; ``largest``: the largest
    sheet resolution that runs on this driver."""
    if int(round(float(ran))) != 2:
        raise LoopCapError(
            f"{kernel} stopped early on --arch {arch()}: the driver ended its loops (Mesa's "
            f"llvmpipe / lavapipe runs at most {LOOP_CAP} loop iterations a shader invocation), "
            f"so its answer would be wrong; this mesh ({mesh}) is too large for the serial "
            f"kernels on this driver. Use a lower --resolution ({largest} or less for a sheet) "
            "or --arch cpu")


# Taichi's advanced IR optimisation is off (``ti.init(advanced_optimization=False)``): measured
# on this 2-core VM, it made the strain solve (strain/al.py solve_al) compile in about 8
# minutes instead of about 20 s on an empty cache, and the kernels it built were no faster
# (hanging at 1.2k, 4k and 16k triangles, drape, tshirt: within the runs' spread of 10-20 %,
# docs/speed/first_run.md, "Optimised kernels"). LLVM's own -O3 runs either way.
# LOOM_FAST_COMPILE=0 switches it on (for a GPU back end, not measured here).
FAST_COMPILE_ENV = "LOOM_FAST_COMPILE"


def compile_mode():
    """This process's compile: 'optimised' with LOOM_FAST_COMPILE=0, else 'fast'."""
    import os
    return "optimised" if os.environ.get(FAST_COMPILE_ENV, "").strip() == "0" else "fast"


def fast_compile():
    """Whether this process compiles fast (after init: what init chose)."""
    if _state.get("fast") is not None:
        return _state["fast"]
    return compile_mode() == "fast"


def cache_dir():
    """Taichi's offline cache folder, known before ti.init (TI_OFFLINE_CACHE_FILE_PATH, else
    Taichi's default, ~/.cache/taichi/ticache)."""
    import os
    path = os.environ.get("TI_OFFLINE_CACHE_FILE_PATH", "")
    if path:
        return path
    from taichi.lang import impl
    return impl.default_cfg().offline_cache_file_path


# Taichi 1.7's front end formats a source excerpt (the code line re-wrapped by textwrap, with a
# line of ^ marks) for every name and statement of a kernel it transforms, to attach to the IR
# as debug info; only error messages read it. Measured (hanging, resolution 9, mapping, warm
# offline cache, fast compile): building a Simulator and running two frames took 7.9 s for the
# first and 3.6-6.9 s for each later one; with the plain excerpt below (the format Taichi itself
# uses on Python < 3.8: location and code line, no wrapping or marks) 5.5 s and 2.2-2.5 s.
# LOOM_TAICHI_DEBUG_INFO=1 keeps Taichi's own (for a kernel compile error's ^ marks).
DEBUG_INFO_ENV = "LOOM_TAICHI_DEBUG_INFO"


def _plain_pos_info(ctx, node):
    lineno = node.lineno + ctx.lineno_offset
    line = ctx.src[node.lineno - 1] if 0 < node.lineno <= len(ctx.src) else ""
    return f'File "{ctx.file}", line {lineno}, in {ctx.func.func.__name__}:\n{line}\n'


def _use_plain_debug_info():
    import os
    if os.environ.get(DEBUG_INFO_ENV, "") not in ("", "0"):
        return
    try:
        from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
    except ImportError:         # another Taichi: leave its front end alone
        return
    if hasattr(ASTTransformerContext, "get_pos_info"):
        ASTTransformerContext.get_pos_info = _plain_pos_info


# Taichi 1.7's front end reads a ti.func's source again (``inspect.getsourcelines``, which
# tokenizes the whole file up to the function) at every call site it inlines: 885 times for
# the strain solve, 1.0 s of its 6.3 s front end under cProfile (hanging, resolution 7, warm
# offline cache: the front end runs cached or not, to find the cache key). The source of a
# function does not change within a process, so it is read once.
def _remember_sources():
    try:
        from taichi.lang import kernel_impl
    except ImportError:
        return
    for name in ("getsourcefile", "getsourcelines"):
        original = getattr(kernel_impl, name, None)
        if original is None or getattr(original, "_loom_remembered", False):
            continue
        kept = {}

        def remembered(func, original=original, kept=kept):
            if func not in kept:
                kept[func] = original(func)
            return kept[func]
        remembered._loom_remembered = True
        setattr(kernel_impl, name, remembered)


# Taichi's offline cache keeps at most 100 MB by default and then drops its least recently used
# quarter: a test run's kernels pushed the demo's strain solver (several MB) out of it.
CACHE_BYTES = 1 << 30


def default_precision(arch):
    return "f32" if arch in F32_ONLY else "f64"


def init(arch="cpu", precision=None, debug=False):
    """Start Taichi once per process. Calling again with the same settings is a no-op;
    with different settings Taichi is reset (all fields are lost). ``precision`` None: f64,
    or f32 on Vulkan and Metal (``F32_ONLY``)."""
    if arch not in ARCHES:
        raise BackendError(f"unknown --arch '{arch}': use one of {', '.join(ARCHES)}")
    requested = arch
    if arch == "gpu":
        # The device decides the rules (f32 only, the host-loop solve), so they follow the
        # back end Taichi picks, not the word "gpu": on a machine whose GPU back end was
        # Vulkan, --arch gpu compiled f64 kernels for it and stopped in a SPIR-V error.
        arch = resolve_gpu()
    if precision is None:
        precision = default_precision(arch)
    if precision not in PRECISIONS:
        raise BackendError(f"unknown --precision '{precision}': use f64 or f32")
    if arch in F32_ONLY and precision == "f64":
        device = arch if requested == arch else f"{requested} (Taichi's {arch} here)"
        raise BackendError(f"--arch {device} has no 64-bit float kernels in Taichi (its SPIR-V "
                           f"back end cannot compile f64 atan2): use --precision f32, or "
                           f"--arch cpu / cuda for f64")
    if _state["arch"] == arch and _state["precision"] == precision:
        return
    _check_module_types(precision)
    if _state["arch"] is not None:
        ti.reset()
    fp = ti.f64 if precision == "f64" else ti.f32
    _use_plain_debug_info()
    _remember_sources()
    from . import launch
    launch.install()            # launches that keep their argument context (launch.py)
    fast = compile_mode() == "fast"
    ti.init(arch=getattr(ti, ARCHES.get(arch, arch)), default_fp=fp, log_level=ti.ERROR,
            debug=debug, offline_cache=True, offline_cache_max_size_of_files=CACHE_BYTES,
            advanced_optimization=not fast)
    _state.update(arch=arch, precision=precision, fast=fast, requested=requested)


def resolve_gpu():
    """The back end Taichi starts for ``ti.gpu`` on this machine ("cuda", "vulkan", "metal",
    ..., or "cpu" when it finds no GPU back end), probed once per process with a throwaway
    ``ti.init``."""
    if _gpu["resolved"] is None:
        from taichi._lib import core as ti_core
        from taichi.lang import impl
        ti.init(arch=ti.gpu, log_level=ti.ERROR, offline_cache=False)
        name = ti_core.arch_name(impl.current_cfg().arch)
        ti.reset()
        _state["arch"] = None           # nothing runs until init starts the real one
        _gpu["resolved"] = "cpu" if name in ("x64", "arm64") else name
    return _gpu["resolved"]


def start_notes():
    """Lines main.py prints after ``init``: which device ``--arch gpu`` started on, and that
    on a GPU of ``ONE_GPU_THREAD`` the solves run as serial kernels."""
    notes = []
    if _state["requested"] == "gpu":
        notes.append(f"loom: --arch gpu started on {_state['arch']} "
                     f"({_state['precision']})")
    if _state["arch"] in ONE_GPU_THREAD:
        notes.append(f"loom: on {_state['arch']} each solve still runs as one serial kernel, "
                     "on a single GPU thread: expect it to be slower than --arch cpu "
                     "(docs/speed/gpu_plan.md)")
    return notes


def _float_types(value):
    """The float types inside a Taichi vector, matrix or struct type (else none)."""
    from taichi.lang.matrix import MatrixType
    from taichi.lang.struct import StructType
    if isinstance(value, MatrixType):
        return [value.dtype]
    if isinstance(value, StructType):
        return [d for m in value.members.values()
                for d in (_float_types(m) if isinstance(m, (MatrixType, StructType)) else [m])]
    return []


def _check_module_types(precision):
    """Refuse to start when any of cloth's module-level Taichi types (``vec3 =
    ti.types.vector(3, float)``, the constraint structs, ...) was already created for the other
    precision: such a type takes the float type Taichi has when its module is imported (f32
    before ti.init), and kernel arguments, arrays and locals of that type would then silently
    run in it. Measured twice: main.py, which imported the scenes first, ran the strain
    projection's metric in f32 under f64 (its frames drifted 3 mm from the library's in 3
    frames); and the benchmarks that imported ``cloth.strain.constraints`` for its method list
    evaluated every constraint in f32 structs (the svd rows of the speed-against-error sweep
    read 1.96e-3 instead of 1.24e-3). Every loaded ``cloth`` module is scanned, so a new type
    cannot slip past the check."""
    import sys
    want = ti.f64 if precision == "f64" else ti.f32
    for module_name, module in list(sys.modules.items()):
        if module is None or not (module_name == "cloth" or module_name.startswith("cloth.")):
            continue
        for type_name, value in list(vars(module).items()):
            for dtype in _float_types(value):
                if dtype in (ti.f32, ti.f64) and dtype != want:
                    have = "f64" if dtype == ti.f64 else "f32"
                    raise BackendError(
                        f"cloth's Taichi types ({module_name}.{type_name}) were created in "
                        f"{have} before backend.init(..., '{precision}'): call "
                        "cloth.backend.init first, before importing the simulator, the scenes "
                        "or the solvers")


def precision():
    return _state["precision"]


def arch():
    return _state["arch"]


def is_initialised():
    return _state["arch"] is not None
