"""Numba settings for the simulator's per-step kernels.

Kernels are compiled once and cached (``cache=True``); ``fastmath`` stays off so results are
IEEE-exact and bitwise reproducible. ``NUMBA_DISABLE_JIT=1`` runs them as plain Python.

LLVM optimises them at level 1 (:data:`OPT_LEVEL`), not Numba's default 3, unless
``NUMBA_OPT`` is set. Without fastmath no level may reorder or fuse floating-point
operations, so the level changes no result: the pinned baselines and a 2000-step nominal log
are bitwise identical at levels 0 to 3. A cold compile of every kernel in one process took
150 s at level 3, 101 s at 2 and 95 s at 1, the step costing the same at each (about 255 µs,
within the host's noise); level 0 compiles in 70 s but leaves the kernels uncacheable ("uses
dynamic globals"), so every process would compile them again.

A slice assigned from an array of the wrong shape raises ValueError without the two shapes in
its message (:func:`_plain_slice_assignment_errors`): Numba's message formats them with its
compiled string code, which every kernel that assigns a slice links in, compiles, optimises
and emits again, some 13 s of a cold compile in one process and paid by each process.

Numba invalidates a cached kernel only when the file that defines it changes, not when a
kernel it calls from another file does: an edit of ``breve_controller.py`` would leave the
cached step kernel running the old controller. So the cache lives in a folder named after a
hash of every source file of this package (:func:`source_stamp`): any edit here starts a fresh
cache. ``NUMBA_CACHE_DIR``, if set, is used as it is; an installed package caches in the
per-user folder of :func:`pipeline.paths.user_cache_dir`.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from numba import njit
from numba.core import config

from pipeline.paths import source_checkout, user_cache_dir

SIM_DIR = Path(__file__).resolve().parent
# The files outside this folder whose constants the kernels freeze: the log row's layout and
# the shapes (their blocks, TASK_DOF, MAX_JOINTS; tests/test_control_step.py finds them).
KERNEL_CONSTANTS = (SIM_DIR.parent / "log_layout.py", SIM_DIR.parent / "shapes.py")


def source_stamp(directory: Path = SIM_DIR) -> str:
    """SHA-256 (first 12 hex digits) over the ``*.py`` files of ``directory`` and the files
    of ``KERNEL_CONSTANTS``, by name."""
    h = hashlib.sha256()
    for p in [*sorted(Path(directory).glob("*.py")), *KERNEL_CONSTANTS]:
        h.update(p.name.encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()[:12]


def kernel_cache_dir(directory: Path = SIM_DIR) -> Path:
    """Where this source's compiled kernels are cached: beside the sources in a checkout
    (``make clean`` removes old ones), in the per-user cache folder of an installed package
    (its site-packages may be read-only and is shared by users)."""
    stamp = f"numba-{source_stamp(directory)}"
    if source_checkout():
        return directory / "__pycache__" / stamp
    return user_cache_dir() / stamp


OPT_LEVEL = "1"


def _plain_slice_assignment_errors() -> bool:
    """Make Numba's slice-assignment shape check raise its plain message, "cannot assign slice
    from input of different size" (its generic targets' one), instead of the CPU target's,
    which formats both shapes with compiled string code. Only the text of an error that no
    kernel raises changes. A private hook of Numba (``numba==0.68.1`` in constraints.txt): if
    it is not there, nothing changes; returns whether it was."""
    try:
        from numba.core.typing.templates import builtin_registry
        from numba.np import arrayobj

        stub = arrayobj.raise_with_shape_context
        cpu = arrayobj.ol_raise_with_shape_context_cpu
        plain = arrayobj.ol_raise_with_shape_context_generic
    except (ImportError, AttributeError):
        return False
    done = False
    for func, ty in builtin_registry.globals:
        if func is stub:
            for template in getattr(ty, "templates", ()):
                if getattr(template, "_overload_func", None) is cpu:
                    template._overload_func = staticmethod(plain)
                    done = True
    return done


_plain_slice_assignment_errors()

if not os.environ.get("NUMBA_OPT"):
    # In the environment, not only in Numba's config: processes started from this one (the
    # compile stage's, a sweep's workers) inherit it, and Numba's reload of its config from
    # the environment, at every compilation, keeps it.
    os.environ["NUMBA_OPT"] = OPT_LEVEL
    config.reload_config()

if not os.environ.get("NUMBA_CACHE_DIR"):
    config.CACHE_DIR = str(kernel_cache_dir())

jit = njit(cache=True, fastmath=False, nogil=True)
