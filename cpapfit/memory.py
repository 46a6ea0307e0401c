"""Memory handed back between a design's stages.

A stage's spent meshes outlive it unless collected: trimesh's meshes hold reference cycles (a mesh
and its visuals), which Python frees only when its collector runs, with their caches and Embree
scenes (hundreds of MB on a dense scan). glibc then keeps what was freed in its heaps for reuse
rather than handing it back (`malloc_trim`), so the next stage's peak stands on the last one's.
"""

import contextlib
import ctypes
import gc

try:
    _TRIM = ctypes.CDLL(None).malloc_trim  # glibc's; absent elsewhere (macOS, musl, Windows)
    _TRIM.argtypes = [ctypes.c_size_t]
except (AttributeError, OSError, TypeError):
    _TRIM = None


def release() -> None:
    """Collect unreachable objects and hand the freed heap back to the system where glibc can."""
    gc.collect()
    if _TRIM is not None:
        _TRIM(0)


@contextlib.contextmanager
def settled():
    """`release`, then what lives (the modules loaded, the caller's state) set aside from the
    collector's passes for the duration (`gc.freeze`): each `release` within walks only what was
    made since, and a process forked within shares those pages untouched by the passes."""
    release()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()
