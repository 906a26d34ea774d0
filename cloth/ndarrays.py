"""What every kernel module shares about Taichi ndarrays.

Every kernel in ``cloth`` takes its arrays as ndarray arguments (``A``) and every ``ti.func``
takes them by reference as templates (``T``), so a kernel compiles once per process and not
once per model, solver or obstacle (issue #15; cloth/strain/buffers.py has the measurements).

``zero`` exists because Taichi 1.7's own ``fill`` on a vector or matrix ndarray passes the
value to its fill kernel as a template argument keyed by the value object, so every call
compiled a new kernel (measured: three new kernels per Simulator, and one per non-warm
projection and per Cholesky Newton step before this helper).
"""
import taichi as ti

A = ti.types.ndarray()          # any ndarray; kernels compile once per dtype / dimension
T = ti.template()               # how a ti.func takes an array (by reference)


@ti.kernel
def _zero_elements(arr: A):
    for I in ti.grouped(arr):
        v = arr[I]
        for J in ti.static(ti.grouped(ti.ndrange(*v.get_shape()))):
            v[J] = 0            # written, not multiplied: a NaN becomes 0 too
        arr[I] = v


def zero(arr):
    """Set every element of an ndarray (scalar, vector or matrix elements) to 0."""
    from taichi.lang.matrix import MatrixNdarray, VectorNdarray
    if isinstance(arr, (VectorNdarray, MatrixNdarray)):
        _zero_elements(arr)
    else:
        arr.fill(0)
