"""What every kernel module shares about Taichi ndarrays.

Every kernel in ``cloth`` takes its arrays as ndarray arguments (``A``) and every ``ti.func``
takes them by reference as templates (``T``), so a kernel compiles once per process and not
once per model, solver or obstacle (cloth/strain/buffers.py has the measurements).

``zero`` exists because Taichi 1.7's own ``fill`` on a vector or matrix ndarray passes the
value to its fill kernel as a template argument keyed by the value object, so every call
compiled a new kernel (measured: three new kernels per Simulator, and one per non-warm
projection and per Cholesky Newton step before this helper).

``PackCache`` keeps the argpacks (``ti.types.argpack`` groups of ndarrays) the kernels take
their arrays in: the strain solver's (cloth/strain/buffers.py) and the dynamics'
(cloth/dynamics.py).
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


class PackCache:
    """Argpacks made once per set of arrays and counts: ``get(kind, pack_type, **members)``
    returns the pack of ``members``, made on first use and again only when one of its arrays
    was replaced (a remesh's new bend_ptr, a new stitch capacity, a larger matrix) or one of
    its scalars (a count) changed. Why cache: making a pack of 16 ndarrays costs ~260 us, more
    than a launch with 33 ndarrays (~230 us; 2-core CPU, Taichi 1.7.4), while the look-up
    costs a few. The last two packs of each kind are kept (the strain solver's two metrics,
    and its preconditioner and stubs, alternate). While a pack is kept it holds its arrays,
    so their ids cannot be reused. A pack is never changed once made (why:
    cloth/strain/buffers.py, above MeshPack)."""

    def __init__(self):
        self._made = {}

    def get(self, kind, pack_type, **members):
        key = tuple(a if isinstance(a, (int, float)) else id(a) for a in members.values())
        made = self._made.setdefault(kind, {})
        pack = made.get(key)
        if pack is None:
            if len(made) >= 2:
                made.pop(next(iter(made)))
            pack = made[key] = pack_type(**members)
        return pack


def zero(arr):
    """Set every element of an ndarray (scalar, vector or matrix elements) to 0."""
    from taichi.lang.matrix import MatrixNdarray, VectorNdarray
    if isinstance(arr, (VectorNdarray, MatrixNdarray)):
        _zero_elements(arr)
    else:
        arr.fill(0)


# Rows in and out of ndarrays that have spare capacity (the model's, the solvers'). Taichi's
# own from_numpy / to_numpy move the whole array, and with remeshing the arrays are sized for
# the finest mesh the sizing allows (6x the faces of the hanging sheet, 24 bending entries per
# vertex of that): refilling the model that way cost 7-8 ms per remesh at 900 faces, almost
# all of it rows nobody reads. These move the active rows only (one serial launch each).
@ti.kernel
def _put_scalars(n: ti.i32, n_clear: ti.i32, src: A, dst: A):
    ti.loop_config(serialize=True)
    for i in range(ti.max(n, n_clear)):
        if i < n:
            dst[i] = src[i]
        else:
            dst[i] = 0


@ti.kernel
def _put_scalars_2d(n: ti.i32, n_clear: ti.i32, src: A, dst: A):
    ti.loop_config(serialize=True)
    for i in range(ti.max(n, n_clear)):
        for j in range(dst.shape[1]):
            if i < n:
                dst[i, j] = src[i, j]
            else:
                dst[i, j] = 0


@ti.kernel
def _put_elements(n: ti.i32, n_clear: ti.i32, src: A, dst: A):
    ti.loop_config(serialize=True)
    for i in range(ti.max(n, n_clear)):
        v = dst[i]
        shape = ti.static(v.get_shape())
        if ti.static(len(shape) == 1):
            for c in ti.static(range(shape[0])):
                v[c] = src[i, c] if i < n else 0
        else:
            for r in ti.static(range(shape[0])):
                for c in ti.static(range(shape[1])):
                    v[r, c] = src[i, r, c] if i < n else 0
        dst[i] = v


@ti.kernel
def _get_scalars(n: ti.i32, src: A, out: A):
    ti.loop_config(serialize=True)
    for i in range(n):
        out[i] = src[i]


@ti.kernel
def _get_scalars_2d(n: ti.i32, src: A, out: A):
    ti.loop_config(serialize=True)
    for i in range(n):
        for j in range(src.shape[1]):
            out[i, j] = src[i, j]


@ti.kernel
def _get_elements(n: ti.i32, src: A, out: A):
    ti.loop_config(serialize=True)
    for i in range(n):
        v = src[i]
        shape = ti.static(v.get_shape())
        if ti.static(len(shape) == 1):
            for c in ti.static(range(shape[0])):
                out[i, c] = v[c]
        else:
            for r in ti.static(range(shape[0])):
                for c in ti.static(range(shape[1])):
                    out[i, r, c] = v[r, c]


@ti.kernel
def _copy_rows(n: ti.i32, src: A, dst: A):
    for i in range(n):
        dst[i] = src[i]


def copy_rows(src, dst, n):
    """dst[:n] = src[:n] (ndarrays of one element type), on the device."""
    _copy_rows(int(n), src, dst)


def _is_elements(arr):
    from taichi.lang.matrix import MatrixNdarray, VectorNdarray
    return isinstance(arr, (VectorNdarray, MatrixNdarray))


def put_rows(arr, values, n_clear=0):
    """Write ``values`` (numpy, one row per element) into the first rows of the ndarray
    ``arr`` (1-D, or 2-D of scalars) and zero its rows from there up to ``n_clear`` (the rows
    an earlier, longer fill left behind); the rows beyond are not touched."""
    import numpy as np
    from taichi.lang.util import to_numpy_type
    dtype = to_numpy_type(arr.dtype)
    values = np.ascontiguousarray(values, dtype=dtype)
    n = len(values)
    if n > arr.shape[0] or n_clear > arr.shape[0]:
        raise ValueError(f"{n} rows do not fit an ndarray of {arr.shape[0]}")
    if n == 0:                      # a kernel needs a non-empty array to bind
        values = np.zeros((1,) + values.shape[1:], dtype)
    if _is_elements(arr):
        _put_elements(n, int(n_clear), values, arr)
    elif len(arr.shape) == 2:
        _put_scalars_2d(n, int(n_clear), values.reshape(len(values), arr.shape[1]), arr)
    else:
        _put_scalars(n, int(n_clear), values, arr)


def get_rows(arr, n):
    """The first ``n`` rows of the ndarray ``arr`` (1-D, or 2-D of scalars) as a numpy array
    (float64 for floats), a copy the caller owns."""
    import numpy as np
    from taichi.lang.util import to_numpy_type
    dtype = to_numpy_type(arr.dtype)
    if _is_elements(arr):
        shape, get = tuple(arr.element_shape), _get_elements
    elif len(arr.shape) == 2:
        shape, get = (arr.shape[1],), _get_scalars_2d
    else:
        shape, get = (), _get_scalars
    out = _read_buffer(arr, (max(arr.shape[0], 1),) + shape, dtype)
    get(int(n), arr, out)
    return out[: int(n)].astype(np.float64 if np.issubdtype(dtype, np.floating) else dtype)


# Each array's read-back buffer (numpy, the array's whole capacity), kept while the array
# lives: a kernel called again with the same numpy array replays its launch (cloth/launch.py;
# with a new array at every call each read-back cost Taichi's whole argument walk).
_read_buffers = {}


def _read_buffer(arr, shape, dtype):
    import weakref
    import numpy as np
    key = id(arr)
    kept = _read_buffers.get(key)
    if kept is not None and kept[0]() is arr and kept[1].shape == shape:
        return kept[1]

    def forget(ref, key=key):
        if _read_buffers.get(key, (None,))[0] is ref:
            del _read_buffers[key]
    buffer = np.zeros(shape, dtype)
    _read_buffers[key] = (weakref.ref(arr, forget), buffer)
    return buffer
