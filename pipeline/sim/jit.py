"""Numba settings for the simulator's per-step kernels.

Kernels are compiled once and cached beside their module (``cache=True``); ``fastmath`` stays
off so results are IEEE-exact and bitwise reproducible. ``NUMBA_DISABLE_JIT=1`` runs them as
plain Python.
"""

from numba import njit

jit = njit(cache=True, fastmath=False, nogil=True)
