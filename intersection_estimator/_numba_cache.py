"""numba cache safety: one on-disk cache per version of the kernel sources.

numba keys a ``cache=True`` function's cache on its own source file only, but a compiled
function carries what it calls from other files (and the module constants it reads)
compiled in. With the kernels split over several modules (``topology/``, ``lanes/``), an
edit of one file could leave a stale compiled caller in another. :func:`configure` points
``numba.config.CACHE_DIR`` at a directory named after a hash of every kernel source
(:func:`kernel_sources`), before the first kernel module is imported (it runs from the
package's ``__init__``): any edit of a kernel source selects a fresh cache directory, so
every caller recompiles, and an unchanged tree keeps its warm cache (``make setup`` fills
it for the installed copy). The base directory is ``$NUMBA_CACHE_DIR`` if the user set
one, else the package's ``__pycache__/numba`` if writable, else the user cache directory,
else the system temporary directory.
"""

from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path
import re
import tempfile

__all__ = ['KERNEL_PACKAGES', 'kernel_sources', 'source_key', 'cache_dir', 'configure']

PACKAGE = Path(__file__).resolve().parent
#: Subpackages whose modules hold compiled kernels and the constants they read; every
#: other module that imports numba counts too (``test_numba_cache`` checks the rule).
KERNEL_PACKAGES = ('topology', 'lanes')
_USER_BASE = os.environ.get('NUMBA_CACHE_DIR', '')
_IMPORTS_NUMBA = re.compile(rb'^\s*(import numba|from numba)', re.M)


def kernel_sources() -> list[Path]:
    """The source files whose content keys the cache, in a fixed order."""
    files = {p for d in KERNEL_PACKAGES for p in (PACKAGE / d).rglob('*.py')}
    files |= {p for p in PACKAGE.rglob('*.py') if _IMPORTS_NUMBA.search(p.read_bytes())}
    files.discard(Path(__file__).resolve())
    return sorted(files)


@functools.lru_cache(maxsize=1)
def source_key() -> str:
    """Hash of the kernel sources' relative paths and contents (16 hex digits)."""
    h = hashlib.sha256()
    for p in kernel_sources():
        h.update(p.relative_to(PACKAGE).as_posix().encode() + b'\0' + p.read_bytes() + b'\0')
    return h.hexdigest()[:16]


def _writable(d: Path) -> bool:
    try:
        d.mkdir(parents=True, exist_ok=True)
        return os.access(d, os.W_OK)
    except OSError:
        return False


@functools.lru_cache(maxsize=1)
def cache_dir() -> Path:
    """The cache directory of this package's kernel sources (see the module docstring)."""
    xdg = os.environ.get('XDG_CACHE_HOME') or os.path.join(os.path.expanduser('~'), '.cache')
    bases = [Path(_USER_BASE)] if _USER_BASE else []
    bases += [PACKAGE / '__pycache__' / 'numba', Path(xdg) / 'intersection_estimator' / 'numba',
              Path(tempfile.gettempdir()) / 'intersection_estimator_numba']
    for base in bases:
        if _writable(base / source_key()):
            return base / source_key()
    return bases[-1] / source_key()


def configure() -> Path:
    """Point numba's cache at :func:`cache_dir` (idempotent). numba's locator reads
    ``CACHE_DIR`` when a ``cache=True`` function is defined, i.e. when its module is
    imported, so this must run first: the package ``__init__`` calls it."""
    from numba.core import config
    d = cache_dir()
    config.CACHE_DIR = str(d)
    return d
