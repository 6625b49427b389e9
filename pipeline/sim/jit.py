"""Numba settings for the simulator's per-step kernels.

Kernels are compiled once and cached (``cache=True``); ``fastmath`` stays off so results are
IEEE-exact and bitwise reproducible. ``NUMBA_DISABLE_JIT=1`` runs them as plain Python.

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


def source_stamp(directory: Path = SIM_DIR) -> str:
    """SHA-256 (first 12 hex digits) over the ``*.py`` files of ``directory``, by name."""
    h = hashlib.sha256()
    for p in sorted(Path(directory).glob("*.py")):
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


if not os.environ.get("NUMBA_CACHE_DIR"):
    config.CACHE_DIR = str(kernel_cache_dir())

jit = njit(cache=True, fastmath=False, nogil=True)
