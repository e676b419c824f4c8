"""Where in numba's cache directory petrobot's compiled kernels go: one place per source module,
whatever directory the checkout or install is in (imports numba; no I/O of its own).

numba names a function's cache folder after the absolute path of its source directory
(``analysis_<sha1 of /path/to/coordinator/analysis>``), so a second checkout of the same commit
(a fresh clone, a CI workspace, a copy) compiles every kernel again: about 55 s on two cores before
the first answer of ``petrobot analyze`` on a net the symbolic engine takes. numba (0.68) checks that
a cached function is still valid by a hash of its source file's content, not by its modification
time, so the path adds nothing to that check. :class:`CheckoutLocator` names the
folder after the module's package instead (``petrobot-coordinator.analysis``): every checkout with
the same source shares one compile; a checkout with other source finds the cache stale and compiles
(and a function at another line is another entry). :func:`install` puts the class first among
numba's locators, called by :func:`~coordinator.analysis.jit.configure` (a user's
``NUMBA_CACHE_LOCATOR_CLASSES`` replaces numba's list, this class included). It is not named
in that environment variable, which child processes would inherit, and in which numba would then
fail on every cached function of a Python that cannot import petrobot. Functions outside the
``coordinator`` package keep numba's own locators.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from numba.core import caching

__all__ = ["CheckoutLocator", "install", "subpath"]

#: the directory that holds the ``coordinator`` package (a checkout's root, or site-packages)
_ROOT = Path(__file__).resolve().parents[2]

# numba's locator for NUMBA_CACHE_DIR: public in numba 0.68, private in older releases
_Base: Any = getattr(caching, "UserProvidedCacheLocator", None) or getattr(caching, "_UserProvidedCacheLocator")
# what holds numba's own locators, in the order it tries them
_Impl: Any = getattr(caching, "CacheImpl", None) or getattr(caching, "_CacheImpl", None)
# source stamps are content hashes (the folder may then be shared); older numba stamps mtime and size
_CONTENT_STAMPS = hasattr(caching, "_hash_source_file")


def subpath(py_file: str) -> str | None:
    """The cache folder's name for a source file of the ``coordinator`` package
    (``coordinator/analysis/mdd_kernel.py`` → ``petrobot-coordinator.analysis``); None for a
    file outside it."""
    folder = Path(py_file).resolve().parent
    try:
        rel = folder.relative_to(_ROOT)
    except ValueError:
        return None
    if not rel.parts or rel.parts[0] != "coordinator":
        return None
    return "petrobot-" + ".".join(rel.parts)


class CheckoutLocator(_Base):  # type: ignore[misc]
    """numba's locator for ``NUMBA_CACHE_DIR`` with a folder named by :func:`subpath` instead of
    by the source directory's absolute path (module docstring)."""

    @classmethod
    def get_suitable_cache_subpath(cls, py_file: str) -> str:
        name = subpath(py_file)
        assert name is not None  # from_function makes locators for the package's files only
        return name

    @classmethod
    def from_function(cls, py_func: Any, py_file: str) -> Any:
        """A locator for a function of the ``coordinator`` package (numba's checks: the file
        exists, the folder is writable); None for any other, which numba's next locator takes."""
        if subpath(py_file) is None:
            return None
        return super().from_function(py_func, py_file)


def install() -> bool:
    """Put :class:`CheckoutLocator` first in numba's list of locators (once); False, and numba's
    own folders per checkout path stay, when this numba has no such list or checks cached functions
    by their file's time stamp rather than its content (the folder could then not be shared)."""
    classes = getattr(_Impl, "_locator_classes", None)
    if not _CONTENT_STAMPS or not isinstance(classes, list):
        return False
    if CheckoutLocator not in classes:
        classes.insert(0, CheckoutLocator)
    return True
