"""One line on stderr before a kernel compile that takes long, with the time it took last time.

Taichi compiles a kernel at its first call (per template variant) and keeps the result in its
offline cache. Cold, the strain solve (strain/al.py ``solve_al``, one kernel for the three
methods) takes about 20 s on a 2-core machine (minutes with LOOM_FAST_COMPILE=0); without a
word the program looks hung.
The callers wrap the first call of each big piece of work::

    with compile_notice.first_use("the fast strain solver", key, seconds=120):
        limiter.project(h)

and the first time a ``key`` is used in this process, a line such as

    loom: compiling the fast strain solver (first use on this machine; last time 118 s)

is printed before the call, unless this machine's record says the same code was compiled
already (then Taichi loads it from its cache and nothing is printed).
The record (``loom_compile_times.json``) sits inside Taichi's offline cache directory, so
emptying the cache empties it too. It maps each key to the fingerprint of what was compiled
(Taichi version, arch, precision, optimisation, the source of the ``cloth`` package) and the
seconds the last cold compile took. Later uses of a key in the same process cost one set
lookup.

Every other kernel compiles in under 2.5 s. A cached strain solve still takes about 9 s to
load: Taichi's CPU cache holds LLVM IR, and LLVM makes the machine code again in every process
(docs/speed/first_run.md); a first use that quick is not taken for a compile (``LOAD_SHARE``).
"""
import contextlib
import hashlib
import json
import os
import sys
import time

RECORD_NAME = "loom_compile_times.json"
# A first call shorter than this was a cache load, not a compile: its time is not kept as the
# estimate for the next cold compile.
COMPILED_ABOVE_S = 5.0
# Nor one shorter than this share of the last compile's time: a change of the cloth package
# that leaves the kernels as they were is announced (the fingerprint changed), and Taichi then
# loads the strain solve from its cache in about 9 s, where compiling it takes about 20 s;
# kept, that 9 s became the next compile's "last time". (A compile that really became that
# much quicker keeps the older time: the notice's estimate errs long, not short.)
LOAD_SHARE = 0.6

# A first compile's estimate per kernel group, cold on 2 cores, in s: (with full optimisation,
# LOOM_FAST_COMPILE=0; the default compile; None: not measured). The strain solve is one
# kernel for the three methods (docs/speed/first_run.md: 494 s optimised for the hanging run,
# 19 s fast); the exact one compiles the active-set re-solves in as well (25 s fast; optimised
# not measured since, 260 s for one method before, scaled as the fast one's 325 -> 494 s). The
# strain solve's host loop (direct.py) has small kernels.
STRAIN_COMPILE_S = {"fast": (480, 20), "exact": (400, 25)}
DYNAMICS_COMPILE_S = (8, None)
COLLISION_COMPILE_S = (6, None)

_used = set()            # keys whose first use in this process is over
_fingerprint = None
# Called before a notice is printed (a progress bar ends its line there).
before_print = []


def strain_estimate(solve, host_loop):
    """The estimate (optimised, fast) in s of the strain solve's first compile, or None for
    the host loop (its kernels are small)."""
    return None if host_loop else STRAIN_COMPILE_S[solve]


def _record_path():
    try:
        from taichi.lang import impl
        base = impl.current_cfg().offline_cache_file_path
    except Exception:       # Taichi not started: no cache to speak of
        return None
    return os.path.join(base, RECORD_NAME) if base else None


def _read(path):
    try:
        with open(path) as fh:
            data = json.load(fh)
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def _write(path, data):
    """Atomic replace: test workers and a second window may write at the same time (the last
    one wins; a lost entry only costs one more notice)."""
    try:
        os.makedirs(os.path.dirname(path), exist_ok=True)
        tmp = f"{path}.{os.getpid()}.tmp"
        with open(tmp, "w") as fh:
            json.dump(data, fh, indent=1, sort_keys=True)
        os.replace(tmp, path)
    except OSError:
        pass


_source_hash = None


def _source():
    global _source_hash
    if _source_hash is None:
        h = hashlib.sha1()
        root = os.path.dirname(os.path.abspath(__file__))
        for folder, dirs, files in sorted(os.walk(root)):
            dirs.sort()
            for name in sorted(files):
                if name.endswith(".py"):
                    with open(os.path.join(folder, name), "rb") as fh:
                        h.update(name.encode() + fh.read())
        _source_hash = h.hexdigest()
    return _source_hash


def fingerprint(arch=None, precision=None, fast=None):
    """What decides whether Taichi's cache holds a kernel: Taichi's version, the arch,
    precision and optimisation level, and the source of every module of the cloth package
    (a change anywhere counts as new code; the cache may still hold it, and then the notice
    was one line too many). Without arguments: this process's (after backend.init)."""
    global _fingerprint
    import taichi as ti
    from . import backend
    if arch is None and precision is None and fast is None:
        if _fingerprint is None:
            _fingerprint = fingerprint(backend.arch(), backend.precision(),
                                       backend.fast_compile())
        return _fingerprint
    h = hashlib.sha1()
    h.update(repr((ti.__version__, arch, precision, bool(fast))).encode())
    h.update(_source().encode())
    return h.hexdigest()[:16]


def used(key):
    """True once ``key``'s first use in this process is over (its kernels are loaded)."""
    return key in _used


def will_compile(key):
    """True when the first use of ``key`` in this process will (probably) compile: not used
    yet here, and this machine's record has no compile of the same code."""
    if key in _used:
        return False
    path = _record_path()
    entry = _read(path).get(key, {}) if path else {}
    return entry.get("fingerprint") != fingerprint()


def notice(what, key, seconds=None):
    """The line printed before a cold compile of ``what`` (None when it will not compile).
    ``seconds``: see ``first_use``."""
    if not will_compile(key):
        return None
    from . import backend
    if isinstance(seconds, tuple):
        seconds = seconds[1] if backend.fast_compile() else seconds[0]
    path = _record_path()
    entry = _read(path).get(key, {}) if path else {}
    est = "the code changed since the last compile" if entry else "first use on this machine"
    if "seconds" in entry:
        est += f"; last time {_duration(entry['seconds'])}"
    elif seconds is not None:
        est += f"; about {_duration(seconds)} on a 2-core machine"
    if not backend.fast_compile():
        est += ", full optimisation"
    return f"loom: compiling {what} ({est})"


def _duration(seconds):
    return f"{seconds:.0f} s" if seconds < 100 else f"{seconds / 60:.1f} min"


@contextlib.contextmanager
def first_use(what, key, seconds=None, stream=None):
    """Around the call that compiles ``key``'s kernels the first time. ``seconds``: the
    estimate to print while this machine has no record of its own (measured, 2-core CPU),
    a number or (with LOOM_FAST_COMPILE=0, the default) with None for unknown."""
    if key in _used:
        yield
        return
    line = notice(what, key, seconds)
    if line is not None:
        for hook in before_print:
            hook()
        print(line, file=stream or sys.stderr, flush=True)
    t0 = time.perf_counter()
    yield
    took = time.perf_counter() - t0
    _used.add(key)
    path = _record_path()
    if path is None:
        return
    data = _read(path)
    entry = dict(data.get(key, {}))
    changed = entry.get("fingerprint") != fingerprint()
    if not changed and line is None:
        return                          # a cache load as recorded: nothing to write
    entry["fingerprint"] = fingerprint()
    last = entry.get("seconds")
    if took >= COMPILED_ABOVE_S and not (last is not None and took < LOAD_SHARE * last):
        entry["seconds"] = round(took, 1)
        entry["date"] = time.strftime("%Y-%m-%d")
    data[key] = entry
    _write(path, data)
