"""Kernel launches without Taichi 1.7's per-call argument walk (every back end).

Taichi 1.7 builds a launch's arguments in Python at every call: it walks each argument, and
each member of an argpack, once to find the compiled variant and once more to write it into
a new launch context. Loom's kernels take argpacks of 6-16 ndarrays, so the walk costs more
than most of them run: measured on the 2-core CPU, with nothing to do, ``al.begin_solve``
(three argpacks) took 656 us a call, ``al.finish_solve`` 362 us, ``al.copy_vectors`` (two
ndarrays) 143 us, while a hanging sheet's frame makes 16 launches.

A kernel called again with the same ndarray and argpack objects (the solvers' packs are made
once and never changed: ``ndarrays.PackCache``) finds the same compiled variant and writes the
same arguments, so the first call's walk is recorded (the launch context's setter calls) and
later calls replay it into a new context, with their own scalar values. (The context itself
cannot be kept: Taichi's launch leaves it pointing at memory it frees.) What takes this
path: positional arguments that are ndarrays, argpacks, C-contiguous numpy arrays (Taichi
passes their data pointer), Python or numpy scalars, small matrices and vectors (their values
are part of the key: an obstacle's pose), and hashable template values, on a kernel without
autodiff or print. Anything else (other numpy arrays, structs, fields as templates, keyword
arguments, a tape) goes Taichi's own way, as does every first call. A recording holds weak
references to its arrays and packs and is replayed only while all of them are alive (so an
id cannot be reused under it); all recordings are dropped with the Taichi runtime they were
made in (``ti.reset``)."""
import weakref

import numpy as np

_KEEP = 16         # recordings kept per kernel (the strain solve alternates two metrics'
#                    packs; the compare view runs three simulators)
# A kernel none of whose recordings was ever replayed (new arrays at every call:
# ``ndarrays.get_rows``' output, Taichi's own to_numpy) stops recording after this many.
_GIVE_UP = 16

_installed = {}
_runtime = [lambda: None]       # a weak reference to the runtime the recordings belong to
_tables = []                    # every kernel's recordings (cleared when the runtime changes)


def install():
    """Route every ``@ti.kernel`` call through ``_call`` (once per process)."""
    if _installed:
        return
    try:
        from taichi.lang import impl, kernel_impl, runtime_ops
        from taichi.lang._ndarray import Ndarray
        from taichi.lang.argpack import ArgPack
        from taichi.lang.enums import AutodiffMode
        from taichi.lang.matrix import Matrix, MatrixType
        from taichi.types import ndarray_type, primitive_types, template
    except ImportError:          # another Taichi: leave its launches alone
        return
    _installed.update(original=kernel_impl.Kernel.__call__, objects=(Ndarray, ArgPack),
                      array_type=ndarray_type.NdarrayType, matrix_type=MatrixType,
                      matrix=Matrix,
                      from_cpp=kernel_impl.handle_exception_from_cpp,
                      get_runtime=impl.get_runtime, sync=runtime_ops.sync,
                      none=AutodiffMode.NONE, template=template,
                      scalar_types=set(primitive_types.real_type_ids)
                      | set(primitive_types.integer_type_ids))
    kernel_impl.Kernel.__call__ = _call


def _call(kernel, *args, **kwargs):
    if not kwargs:
        done, result = _fast_path(kernel, args)
        if done:
            return result
    return _installed["original"](kernel, *args, **kwargs)


class _Table(dict):
    """A kernel's recordings by ``_key``; how many first calls it recorded, whether any
    recording was replayed."""
    recorded, replayed = 0, False


class _Kept:
    """A first call's recording: the compiled variant and the launch context's setter calls."""
    __slots__ = ("refs", "t_kernel", "calls", "scalars")

    def __init__(self, refs, t_kernel, calls, scalars):
        self.refs, self.t_kernel, self.calls = refs, t_kernel, calls
        self.scalars = scalars           # (position in calls, argument position, cast)


def _fast_path(kernel, args):
    """(True, the kernel's result) if this call replayed or recorded its arguments, else
    (False, None): Taichi's own call then runs."""
    runtime = _installed["get_runtime"]()
    if kernel.autodiff_mode != _installed["none"] or runtime.target_tape or \
            runtime.fwd_mode_manager or len(args) != len(kernel.arguments) or kernel.has_print:
        return False, None
    key = _key(kernel, args)
    if key is None:
        return False, None
    if _runtime[0]() is not runtime:          # ti.reset: the recorded kernels are gone
        for table in _tables:
            table.clear()
        _runtime[0] = weakref.ref(runtime)
    table = kernel.__dict__.get("_loom_contexts")
    if table is None:
        table = kernel.__dict__["_loom_contexts"] = _Table()
        _tables.append(table)
    if table.recorded >= _GIVE_UP and not table.replayed:
        return False, None
    kept = table.get(key)
    if kept is not None and all(r() is not None for r in kept.refs):
        table.replayed = True
        calls = list(kept.calls)
        for at, pos, cast in kept.scalars:
            setter, (index, _) = calls[at]
            calls[at] = (setter, (index, cast(args[pos])))
        ctx = kept.t_kernel.make_launch_context()
        for setter, call_args in calls:
            setter(ctx, *call_args)
        prog = runtime.prog
        try:
            prog.launch_kernel(prog.compile_kernel(prog.config(), prog.get_device_caps(),
                                                   kept.t_kernel), ctx)
        except Exception as e:      # as Taichi's own launch reports a kernel's error
            raise _installed["from_cpp"](e) from None
        return True, _result(kernel, ctx)
    compiled_key = kernel.ensure_compiled(*args)
    if kernel.has_print:        # (known once compiled) Taichi's call shows its prints
        return False, None
    table.recorded += 1
    kept, result = _first_launch(kernel, args, key, runtime, compiled_key)
    if kept is not None:
        if len(table) >= _KEEP:
            table.pop(next(iter(table)))
        table[key] = kept
    return True, result


def _key(kernel, args):
    """What identifies a call's recording: the ids of its ndarrays, argpacks and numpy
    arrays, the types of its scalars, the values of its templates and small matrices; None
    when an argument is of another kind."""
    objects, template = _installed["objects"], _installed["template"]
    key = []
    for arg, value in zip(kernel.arguments, args):
        if isinstance(arg.annotation, template):
            if not isinstance(value, (int, float, str, bool)):
                return None
            key.append(("t", value))
        elif isinstance(value, objects):
            key.append(id(value))
        elif isinstance(arg.annotation, _installed["array_type"]):
            if not (isinstance(value, np.ndarray) and value.flags.c_contiguous):
                return None
            key.append(id(value))       # (Taichi passes its data pointer: fixed for its life)
        elif isinstance(arg.annotation, _installed["matrix_type"]):
            # A small matrix or vector (an obstacle's pose): its values are part of the key,
            # and a recording replays them as they were.
            if isinstance(value, _installed["matrix"]):
                value = value.to_numpy()
            try:
                key.append(("m",) + tuple(np.asarray(value, np.float64).ravel().tolist()))
            except (TypeError, ValueError):
                return None
        elif isinstance(value, (int, float, np.integer, np.floating)) and \
                id(arg.annotation) in _installed["scalar_types"]:
            key.append(type(value))
        else:
            return None
    return tuple(key)


class _RecordingContext:
    """A launch context that notes every setter call made on it."""

    def __init__(self, ctx):
        self.ctx, self.calls = ctx, []

    def __getattr__(self, name):
        method = getattr(self.ctx, name)
        if not name.startswith("set_"):       # set_arg_*, set_struct_arg_*
            return method
        unbound = getattr(type(self.ctx), name)

        def noted(*a):
            self.calls.append((unbound, a))
            return method(*a)
        return noted


class _RecordingKernel:
    """Stands in for Taichi's compiled kernel during a first launch: its contexts record."""

    def __init__(self, t_kernel):
        self.t_kernel, self.ctx = t_kernel, None

    def make_launch_context(self):
        self.ctx = _RecordingContext(self.t_kernel.make_launch_context())
        return self.ctx


class _RecordingProgram:
    """Stands in for Taichi's program during a first launch: it hands the real kernel and
    context on (every other use is passed through)."""

    def __init__(self, prog):
        self._prog = prog

    def compile_kernel(self, config, caps, kernel):
        real = kernel.t_kernel if isinstance(kernel, _RecordingKernel) else kernel
        return self._prog.compile_kernel(config, caps, real)

    def launch_kernel(self, compiled, ctx):
        real = ctx.ctx if isinstance(ctx, _RecordingContext) else ctx
        return self._prog.launch_kernel(compiled, real)

    def __getattr__(self, name):
        return getattr(self._prog, name)


def _first_launch(kernel, args, key, runtime, compiled_key):
    """Taichi's own launch of this call (``key`` its ``_key``): (its recording, the
    result)."""
    t_kernel = kernel.compiled_kernels[compiled_key]
    prog, recording = runtime.prog, _RecordingKernel(t_kernel)
    runtime.prog = _RecordingProgram(prog)
    try:
        result = kernel.launch_kernel(recording, *args)
    finally:
        runtime.prog = prog
    calls = recording.ctx.calls if recording.ctx is not None else None
    if not calls:
        return None, result
    # The key says each argument's kind: an id (an array or pack), a type (a scalar, set in
    # the context at its slot among the arguments that are not templates), a tuple (a
    # template's value, which has no slot, or a matrix's, replayed as recorded).
    refs, slot_of, slot = [], {}, 0
    for pos, (part, value) in enumerate(zip(key, args)):
        if isinstance(part, int):
            refs.append(weakref.ref(value))
        elif isinstance(part, type):
            slot_of[(slot,)] = pos
        if not (isinstance(part, tuple) and part[0] == "t"):
            slot += 1
    scalars = []
    for at, (setter, call_args) in enumerate(calls):
        pos = slot_of.get(tuple(call_args[0]))
        if pos is not None:
            scalars.append((at, pos, float if setter.__name__ == "set_arg_float" else int))
    if len(scalars) != len(slot_of):          # a scalar was not set where expected
        return None, result
    return _Kept(tuple(refs), t_kernel, tuple(calls), tuple(scalars)), result


def _result(kernel, ctx):
    """The kernel's return value read from the context, as Taichi's ``launch_kernel`` does."""
    ret_types = kernel.return_type
    if ret_types is None:
        return None
    _installed["sync"]()
    ret = [kernel.construct_kernel_ret(ctx, t, (i,)) for i, t in enumerate(ret_types)]
    return ret[0] if len(ret_types) == 1 else ret
