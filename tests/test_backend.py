"""Taichi start-up (cloth/backend.py): a kernel compile error still says where it is, with the
plain debug info and the remembered sources Loom gives Taichi's front end to compile faster."""
import pytest
import taichi as ti


@ti.kernel
def _broken(n: int) -> float:
    total = 0.0
    for i in range(n):
        total += undefined_name_here * i  # noqa: F821 (the error under test)
    return total


def test_compile_error_names_the_file_line_and_code():
    from cloth import backend
    from taichi.lang.ast.ast_transformer_utils import ASTTransformerContext
    assert ASTTransformerContext.get_pos_info is backend._plain_pos_info
    with pytest.raises(ti.TaichiCompilationError) as err:
        _broken(3)
    msg = str(err.value)
    assert "test_backend.py" in msg and "undefined_name_here" in msg
    line = next(i for i, text in enumerate(open(__file__), 1) if "undefined_name_here *" in text)
    assert f"line {line}" in msg


def test_the_front_end_reads_each_functions_source_once():
    """Taichi's front end gets a function's source through ``kernel_impl.getsourcelines`` at
    every inlined call: the same lines and first line number as Taichi's own reader, read
    once per function (a second call returns the same object, not a new reading)."""
    from taichi.lang import _wrap_inspect, kernel_impl
    first = kernel_impl.getsourcelines(run_child)
    assert first == _wrap_inspect.getsourcelines(run_child)
    assert kernel_impl.getsourcelines(run_child) is first
    assert kernel_impl.getsourcefile(run_child) == _wrap_inspect.getsourcefile(run_child)


def run_child(code):
    """``code`` in a fresh Python process at the repository's root (a second ti.init in this
    one would reset its fields)."""
    import os
    import subprocess
    import sys
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    return subprocess.run([sys.executable, "-c", code], cwd=root, capture_output=True,
                          text=True, timeout=300)


def test_init_refuses_types_created_in_the_other_precision():
    """Module-level Taichi types made before ti.init are f32; starting f64 afterwards would
    run them in f32 silently (main.py did). backend.init stops with the fix instead."""
    r = run_child("import cloth.simulator\n"
                  "from cloth import backend\n"
                  "try:\n"
                  "    backend.init('cpu', 'f64')\n"
                  "except backend.BackendError as err:\n"
                  "    print('refused:', err)\n")
    assert "refused:" in r.stdout and "call cloth.backend.init first" in r.stdout, r.stderr


def test_types_made_on_import_are_all_checked_and_the_benchmarks_import_none():
    """Every module-level Taichi type of cloth is checked, structs too: importing the
    constraint structs before ti.init is refused (the benchmarks did, and evaluated every
    constraint in f32 under f64). And every benchmark module, the settings and the scenes can
    be imported before a program picks its precision: none creates a Taichi type on import."""
    import glob
    import os
    import subprocess
    import sys
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    run = lambda code: subprocess.run([sys.executable, "-c", code], cwd=root,
                                      capture_output=True, text=True, timeout=300)
    init = ("from cloth import backend\n"
            "try:\n"
            "    backend.init('cpu', 'f64'); print('started')\n"
            "except backend.BackendError as err:\n"
            "    print('refused:', err)\n")
    r = run("import cloth.strain.constraints\n" + init)
    assert "refused:" in r.stdout and "Constraints" in r.stdout, r.stdout + r.stderr
    names = sorted(os.path.basename(f)[:-3] for f in glob.glob(os.path.join(root, "benchmarks",
                                                                            "*.py")))
    # The settings and the scenes too (a benchmark once read a default from cloth.settings
    # before its children chose f64, and cloth.settings imported the constraints).
    r = run("".join(f"import benchmarks.{n}\n" for n in names if n != "__init__")
            + "import cloth.settings\nimport scenes\n" + init)
    assert "started" in r.stdout, r.stdout + r.stderr


def test_arch_gpu_follows_the_device_taichi_starts():
    """``--arch gpu`` takes the rules of the back end Taichi picks: where that is Vulkan or
    Metal the run is f32 (an f64 kernel stopped in a SPIR-V error there), and start-up says
    which device it got; an explicit f64 on such a device is refused with the fix."""
    r = run_child("from cloth import backend\n"
                  "backend.init('gpu')\n"
                  "print('started', backend.arch(), backend.precision())\n"
                  "print('notes', backend.start_notes())\n"
                  "try:\n"
                  "    backend.init('gpu', 'f64')\n"
                  "    print('f64 ok')\n"
                  "except backend.BackendError as err:\n"
                  "    print('refused:', err)\n")
    assert r.returncode == 0, r.stderr
    lines = dict(line.split(" ", 1) for line in r.stdout.splitlines() if " " in line)
    arch, precision = lines["started"].split()
    assert arch != "gpu" and f"started on {arch} ({precision})" in lines["notes"]
    from cloth import backend
    if arch in backend.F32_ONLY:
        assert precision == "f32"
        assert "--arch gpu (Taichi's" in lines["refused:"] and "--precision f32" in \
            lines["refused:"]
    else:
        assert precision == "f64" and "f64" in lines
