"""Where numba keeps the compiled state-space search, and whether it is there already (reads and
sets environment variables and asks numba; opens no file itself, beyond reading a kernel's
source a second time for :func:`interpreted`).

numba compiles :mod:`.reach_kernel` on its first use on a machine and caches the machine code
(``cache=True``). By default it writes the cache beside the source, in
``coordinator/analysis/__pycache__``, which a system-wide install cannot write. :func:`configure`
points numba at the user's cache directory instead — ``$XDG_CACHE_HOME/petrobot/numba`` or
``~/.cache/petrobot/numba`` (the XDG Base Directory convention) — by setting ``NUMBA_CACHE_DIR``
before numba is imported, unless the user has set it. It also sets numba's optimisation level to 1
(``NUMBA_OPT``, again only when the user has not set it and numba is not imported yet): on this
search, level 1 compiles about 15 % faster than numba's default 3 and runs as fast or faster
(measured on the MCC models and Kanban N = 4, 5; docs/analysis.md, section 2).
:func:`coordinator.analysis.statespace.search_is_compiled` tells a command whether the next use will
compile (so it can say so on stderr) or load the cache. Each compiled module calls :func:`configure`
before it imports numba, so whoever imports it first, the cache lands in the user's directory.
There a module's kernels have one folder whatever the checkout's path (:mod:`.jit_locator`): a
fresh clone of the same source loads what another one compiled.

:func:`configure` also silences numba's notice that code in object mode "won't allow parallel
execution despite nogil=True": both kernels release the GIL (``nogil``) and take it back only for
a moment, in their object-mode hooks (the search's progress report every 65,536 markings, the
saturation's watch every million steps), which is what nogil is asked for.

:func:`interpreted` gives the same source run by the interpreter, with no compile: a second copy
of a kernel module without its ``njit`` decorators. :func:`.statespace.explore` uses it for a
small net while the compiled search is not in the cache yet (docs/analysis.md, section 2).
"""

from __future__ import annotations

import ast
import functools
import os
import sys
import warnings
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import Any

__all__ = ["cache_dir", "configure", "interpreted"]


def cache_dir(environ: dict[str, str] | None = None) -> Path:
    """The directory petrobot gives numba for its cache: ``$XDG_CACHE_HOME/petrobot/numba`` when
    XDG_CACHE_HOME is set to an absolute path, else ``~/.cache/petrobot/numba``."""
    env = os.environ if environ is None else environ
    base = env.get("XDG_CACHE_HOME", "")
    root = Path(base) if base and os.path.isabs(base) else Path(env.get("HOME") or Path.home()) / ".cache"
    return root / "petrobot" / "numba"


def configure() -> str:
    """Point numba's cache at :func:`cache_dir` unless ``NUMBA_CACHE_DIR`` is set (and its
    optimisation level at 1 unless ``NUMBA_OPT`` is set), then import numba and put
    :class:`.jit_locator.CheckoutLocator` first among its cache locators; return the cache
    directory numba will use. Must run before the compiled functions are defined (before
    :mod:`.reach_kernel` is imported); if numba itself is already imported, its configuration is
    updated as well."""
    warnings.filterwarnings("ignore", message="Code running in object mode won't allow parallel execution")
    if "NUMBA_OPT" not in os.environ and "numba" not in sys.modules:
        os.environ["NUMBA_OPT"] = "1"
    chosen = os.environ.get("NUMBA_CACHE_DIR", "")
    if not chosen:
        chosen = str(cache_dir())
        os.environ["NUMBA_CACHE_DIR"] = chosen
        config = sys.modules.get("numba.core.config")
        if config is not None and not getattr(config, "CACHE_DIR", ""):
            config.CACHE_DIR = chosen  # type: ignore[attr-defined]
    from coordinator.analysis import jit_locator  # imports numba, configured above

    jit_locator.install()
    return chosen


def interpreted(module: ModuleType) -> ModuleType:
    """A second copy of the kernel ``module`` whose functions run in the Python interpreter.

    The module's source file is parsed, its functions' ``njit`` decorators are left out, and the
    rest is executed as a new module, ``<name>_interpreted`` (line numbers kept, so tracebacks
    point into the source): one source serves both, nothing is compiled, and nothing global of
    numba's is touched (``NUMBA_DISABLE_JIT`` would reach every module a thread imports
    meanwhile). An ``objmode`` block runs as a plain block in the interpreter. Machine integers
    wrap silently in compiled code, and the hashes rely on that; numpy scalars wrap the same way
    but warn, so the public functions (the module's ``__all__``) run with numpy's overflow
    warnings off.

    About a thousand times slower than the compiled code (a few thousand markings a second on the
    MCC models of tests/data) and ready in well under a second: worth it for a small net while
    the compiled code is not in numba's cache yet. Configures numba first (:func:`configure`).

    Raises:
        ImportError: if the module's source file cannot be found or read.
    """
    configure()
    origin = getattr(module, "__file__", None)
    if not origin:
        raise ImportError(f"{module.__name__} has no source file to interpret")
    try:
        source = Path(origin).read_text(encoding="utf-8")
    except OSError as exc:
        raise ImportError(f"cannot read the source of {module.__name__}: {exc}") from exc
    tree = ast.parse(source, filename=origin)
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef):
            node.decorator_list = [d for d in node.decorator_list if not _is_njit(d)]
    twin = ModuleType(f"{module.__name__}_interpreted")
    twin.__file__ = origin
    exec(compile(tree, origin, "exec"), twin.__dict__)  # noqa: S102 - our own module's source
    for name in getattr(twin, "__all__", ()):
        value = getattr(twin, name)
        if callable(value) and not isinstance(value, type):
            setattr(twin, name, _wrapping(value))
    return twin


def _is_njit(decorator: ast.expr) -> bool:
    target = decorator.func if isinstance(decorator, ast.Call) else decorator
    return (isinstance(target, ast.Name) and target.id == "njit") or (
        isinstance(target, ast.Attribute) and target.attr == "njit")


def _wrapping(function: Callable[..., Any]) -> Callable[..., Any]:
    import numpy as np

    @functools.wraps(function)
    def call(*args: Any, **kwargs: Any) -> Any:
        with np.errstate(over="ignore"):
            return function(*args, **kwargs)

    return call
