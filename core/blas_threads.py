"""One BLAS thread while tracking.

NumPy's and SciPy's wheels bundle OpenBLAS, which splits even the local fit's small products and solves
(30 x 30 systems, 2000 x 30 Jacobians) over every core and then spins waiting for them. The tracker already
keeps both cores busy (the numba rasteriser's threads, the next frame's landmark model in a worker thread),
so those BLAS threads only contend: with one, the local fit takes about a third less time (docs/defaults.md,
"blas_threads"). Best effort: where no OpenBLAS is found (another BLAS, an unusual NumPy build) nothing changes.
"""
import contextlib
import ctypes
import glob
import importlib.util
import os

_SETTERS = ("openblas_set_num_threads", "openblas_set_num_threads64_", "scipy_openblas_set_num_threads64_",
            "scipy_openblas_set_num_threads")
_GETTERS = ("openblas_get_num_threads", "openblas_get_num_threads64_", "scipy_openblas_get_num_threads64_",
            "scipy_openblas_get_num_threads")


def _openblas_libraries():
    """The OpenBLAS libraries bundled with numpy and scipy (numpy.libs, numpy/.dylibs, scipy.libs...)."""
    found = []
    for package in ("numpy", "scipy"):
        spec = importlib.util.find_spec(package)
        if spec is None or not spec.submodule_search_locations:
            continue
        root = list(spec.submodule_search_locations)[0]
        for folder in (f"{root}.libs", os.path.join(root, ".libs"), os.path.join(root, ".dylibs")):
            found += glob.glob(os.path.join(folder, "*openblas*"))
    return found


def _functions():
    """(setter, getter) of every OpenBLAS already loaded (RTLD_NOLOAD: a library not in use is not loaded;
    on Windows, which lacks the flag, it is, harmlessly)."""
    import numpy  # noqa: F401  (its OpenBLAS is the one the tracker's products use)

    pairs = []
    for path in _openblas_libraries():
        try:
            lib = ctypes.CDLL(path, mode=getattr(os, "RTLD_NOLOAD", 0))
        except OSError:
            continue
        setter = next((getattr(lib, n) for n in _SETTERS if hasattr(lib, n)), None)
        getter = next((getattr(lib, n) for n in _GETTERS if hasattr(lib, n)), None)
        if setter is not None and getter is not None:
            getter.restype = ctypes.c_int
            pairs.append((setter, getter))
    return pairs


_FOUND = None


def _cached_functions():
    global _FOUND
    if _FOUND is None:
        _FOUND = _functions()
    return _FOUND


@contextlib.contextmanager
def blas_threads(n=1):
    """Within the block, OpenBLAS (numpy's, and scipy's when loaded at the first call) uses `n` threads; the
    previous counts come back after."""
    pairs = _cached_functions()
    before = [getter() for _, getter in pairs]
    for setter, _ in pairs:
        setter(int(n))
    try:
        yield len(pairs)
    finally:
        for (setter, _), count in zip(pairs, before):
            setter(int(count))


def current_blas_threads():
    """Thread counts of the OpenBLAS libraries found (empty when none is)."""
    return [getter() for _, getter in _functions()]
