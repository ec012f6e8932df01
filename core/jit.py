"""numba's njit with an on-disk cache that works under both names the package is imported as."""
import os
import re

from numba import njit


# ---------------------------------------------------------------------------------------- JIT cache
# numba's on-disk cache names a compiled function's module inside the cached data. The kernels are imported
# as `markerless_mocap.core.render.fast` (CLI, tests) and as `bl_ext.<repo>.markerless_mocap...` (Blender),
# and one process cannot load what the other cached (ModuleNotFoundError). So each importing module name
# gets its own cache folder (numba's own locators with one more path component).
def _module_keyed(base):
    class ModuleKeyedLocator(base):
        def __init__(self, py_func, py_file):
            super().__init__(py_func, py_file)
            tag = re.sub(r"[^A-Za-z0-9_.-]", "_", py_func.__module__)
            self._cache_path = os.path.join(self._cache_path, f"numba-{tag}")

    ModuleKeyedLocator.__name__ = f"ModuleKeyed{base.__name__}"
    return ModuleKeyedLocator


try:
    from numba.core import caching as _caching

    class _ModuleKeyedImpl(_caching.CompileResultCacheImpl):
        _locator_classes = [_module_keyed(c) for c in (_caching.UserProvidedCacheLocator,
                                                       _caching.InTreeCacheLocator,
                                                       _caching.UserWideCacheLocator)]

    class _ModuleKeyedCache(_caching.FunctionCache):
        _impl_class = _ModuleKeyedImpl
except (ImportError, AttributeError):  # a numba without these internals: its default cache
    _ModuleKeyedCache = None


def jit(**options):
    """njit with the module-keyed disk cache (numba's default cache if that cannot be set up)."""
    def wrap(fn):
        dispatcher = njit(cache=False, **options)(fn)
        try:
            dispatcher._cache = _ModuleKeyedCache(dispatcher.py_func)
        except Exception:  # noqa: BLE001  (changed numba internals, or no usable cache folder)
            try:
                dispatcher.enable_caching()
            except Exception:  # noqa: BLE001  (nowhere to cache: compile in every session)
                pass
        return dispatcher
    return wrap
