"""Taichi start-up in one place: architecture and floating-point precision.

Taichi fixes the default float type at ``ti.init``; every field and kernel in ``cloth`` uses
``float`` (Taichi's default float), so one call here decides f32 or f64 for the whole run.
"""
import taichi as ti

ARCHES = {"cpu": "cpu", "gpu": "gpu", "cuda": "cuda", "vulkan": "vulkan", "metal": "metal"}
PRECISIONS = ("f64", "f32")

_state = {"arch": None, "precision": None}


class BackendError(RuntimeError):
    """Raised when Taichi cannot start with the requested settings."""


def init(arch="cpu", precision="f64", debug=False):
    """Start Taichi once per process. Calling again with the same settings is a no-op;
    with different settings Taichi is reset (all fields are lost)."""
    if arch not in ARCHES:
        raise BackendError(f"unknown --arch '{arch}': use one of {', '.join(ARCHES)}")
    if precision not in PRECISIONS:
        raise BackendError(f"unknown --precision '{precision}': use f64 or f32")
    if _state["arch"] == arch and _state["precision"] == precision:
        return
    if _state["arch"] is not None:
        ti.reset()
    fp = ti.f64 if precision == "f64" else ti.f32
    ti.init(arch=getattr(ti, ARCHES[arch]), default_fp=fp, log_level=ti.ERROR,
            debug=debug, offline_cache=True)
    _state.update(arch=arch, precision=precision)


def precision():
    return _state["precision"]


def is_initialised():
    return _state["arch"] is not None
