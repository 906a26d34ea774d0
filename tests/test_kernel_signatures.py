"""No kernel in ``cloth/`` takes more than MAX_PARAMS parameters: arrays that belong together
travel in named argpacks (cloth/strain/buffers.py, cloth/dynamics.py) with the counts that size
them, and a kernel's scalar controls in an array (``budget``, ``motion``), so a call cannot
misorder a long run of positional arguments. Read from the source (no Taichi)."""
import ast
import pathlib

ROOT = pathlib.Path(__file__).resolve().parent.parent
MAX_PARAMS = 12


def _is_kernel(node):
    return any((isinstance(d, ast.Attribute) and d.attr == "kernel") or
               (isinstance(d, ast.Name) and d.id == "kernel") for d in node.decorator_list)


def kernels():
    """(path, line, name, parameter count) of every @ti.kernel under cloth/."""
    out = []
    for path in sorted((ROOT / "cloth").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.FunctionDef) and _is_kernel(node):
                out.append((path.relative_to(ROOT), node.lineno, node.name, len(node.args.args)))
    return out


def test_no_kernel_takes_more_than_twelve_parameters():
    found = kernels()
    assert len(found) > 40, "the scan found too few kernels: did the decorator change?"
    wide = [f"{p}:{line} {name} ({n})" for p, line, name, n in found if n > MAX_PARAMS]
    assert not wide, "kernels over %d parameters: %s" % (MAX_PARAMS, ", ".join(wide))
