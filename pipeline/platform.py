"""The platform a log was made on: what, beside the code and the libraries, decides its bits.

The same spec, code and locked libraries give the same bits only on the same platform
(docs/reproducibility.md): the CPU target the Numba kernels were compiled for, the kernel
OpenBLAS picked for this processor at run time (NumPy and SciPy each load their own build),
the SIMD loops NumPy dispatched to, glibc's libm (which also dispatches on the CPU's
features), and the thread counts. :func:`fingerprint` reads them once, as a
:class:`Platform`; :meth:`Platform.key` hashes the parts that decide the bits, and the rest
(the CPU's model name, the environment variables that set the counts or force a kernel) is
recorded to explain a difference, not to key it.

Logs carry it as ``pipeline.platform`` (:mod:`pipeline.logs`); the pinned baselines compare
bitwise when a pin's key is this platform's key, within measured tolerances otherwise
(:mod:`pipeline.claims.baselines`).
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
from dataclasses import asdict, dataclass, fields
from pathlib import Path

# The host features that decide which code runs where the choice is made at run time, not by
# the Numba target: glibc's libm (its FMA and AVX2 variants of exp, log, sin, pow), NumPy's
# dispatched loops (AVX2, AVX-512) and OpenBLAS's kernel. LLVM's names.
DISPATCH_FEATURES = ("sse4.2", "avx", "avx2", "fma", "avx512f", "avx512dq", "avx512cd",
                     "avx512bw", "avx512vl")
THREAD_ENV = ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS",
              "MKL_NUM_THREADS")
# The parts of a Platform that decide the bits (see the class); the others are informative.
KEY_FIELDS = ("machine", "libc", "kernel_cpu", "kernel_features", "cpu_flags", "numpy_simd",
              "blas", "numba_threads")


@dataclass(frozen=True)
class BlasLibrary:
    """One BLAS loaded in this process, as threadpoolctl reports it."""

    internal_api: str  # "openblas", "mkl", …
    prefix: str  # the library's file name without its hash, e.g. "libscipy_openblas64_"
    version: str
    architecture: str  # the kernel picked for this CPU (OpenBLAS's core type)
    num_threads: int
    threading_layer: str


@dataclass(frozen=True)
class Platform:
    """What a run's bits depend on beyond the code and the library versions.

    Deciding (in :meth:`key`): ``machine`` (``platform.machine()``), ``libc`` (name and
    version), ``kernel_cpu`` and ``kernel_features`` (the CPU and features Numba compiles the
    kernels for: ``NUMBA_CPU_NAME``/``NUMBA_CPU_FEATURES`` if set, else the host's),
    ``cpu_flags`` (the host's features of ``DISPATCH_FEATURES`` present), ``numpy_simd`` (the
    SIMD targets NumPy dispatches to here), ``blas`` (each loaded BLAS, its kernel and thread
    count), ``numba_threads``. Informative: ``cpu_model`` (``/proc/cpuinfo``'s model name,
    else ``platform.processor()``), ``host_cpu`` (LLVM's name for the host), ``thread_env``
    (the variables of ``THREAD_ENV`` that are set), ``openblas_coretype`` (the variable that
    forces OpenBLAS's kernel, when set; its effect is in ``blas``).
    """

    machine: str
    libc: str
    kernel_cpu: str
    kernel_features: str
    cpu_flags: tuple[str, ...]
    numpy_simd: tuple[str, ...]
    blas: tuple[BlasLibrary, ...]
    numba_threads: int
    cpu_model: str
    host_cpu: str
    thread_env: dict[str, str]
    openblas_coretype: str

    def key(self) -> str:
        """16 hex digits over the deciding parts: equal keys, equal bits (same code and
        libraries given)."""
        parts = {k: v for k, v in self.to_dict().items() if k in KEY_FIELDS}
        return hashlib.sha256(json.dumps(parts, sort_keys=True).encode()).hexdigest()[:16]

    def summary(self) -> str:
        """One line for a person: CPU, kernel target, BLAS kernels and threads."""
        blas = ", ".join(dict.fromkeys(f"{b.internal_api} {b.architecture} ×{b.num_threads}"
                                       for b in self.blas)) or "no BLAS"
        forced = f" (OPENBLAS_CORETYPE={self.openblas_coretype})" if self.openblas_coretype \
            else ""
        return (f"{self.cpu_model or 'unknown CPU'}, kernels for {self.kernel_cpu}, "
                f"{blas}{forced}, NumPy SIMD {'+'.join(self.numpy_simd) or 'baseline'}, "
                f"{self.machine} {self.libc}")

    def to_dict(self) -> dict:
        d = asdict(self)
        d["blas"] = [asdict(b) for b in self.blas]
        d["cpu_flags"], d["numpy_simd"] = list(self.cpu_flags), list(self.numpy_simd)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Platform:
        """The record of :meth:`to_dict` (as a log stores it); a KeyError or TypeError if it
        is not one."""
        names = {f.name for f in fields(cls)}
        if set(d) != names:
            raise KeyError(f"platform record keys {sorted(set(d) ^ names)}")
        return cls(**{**d, "blas": tuple(BlasLibrary(**b) for b in d["blas"]),
                      "cpu_flags": tuple(d["cpu_flags"]),
                      "numpy_simd": tuple(d["numpy_simd"])})


def describe(record: dict | None) -> str:
    """:meth:`Platform.summary` of a stored record, or why there is none."""
    if record is None:
        return "an unknown platform (the log records none)"
    try:
        return Platform.from_dict(record).summary()
    except (KeyError, TypeError):
        return "an unreadable platform record"


def differences(a: Platform, b: Platform) -> list[str]:
    """The deciding fields in which ``a`` and ``b`` differ, by name."""
    da, db = a.to_dict(), b.to_dict()
    return [k for k in KEY_FIELDS if da[k] != db[k]]


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.partition(":")[2].strip()
    except OSError:
        pass
    return platform.processor()


def _blas() -> tuple[BlasLibrary, ...]:
    # NumPy and SciPy each bring their own OpenBLAS; SciPy's is loaded only by scipy.linalg.
    import numpy  # noqa: F401
    import scipy.linalg  # noqa: F401
    from threadpoolctl import threadpool_info

    libs = [BlasLibrary(str(i.get("internal_api", "")), str(i.get("prefix", "")),
                        str(i.get("version") or ""), str(i.get("architecture") or ""),
                        int(i.get("num_threads", 0)), str(i.get("threading_layer", "")))
            for i in threadpool_info() if i.get("user_api") == "blas"]
    return tuple(sorted(libs, key=lambda b: (b.prefix, b.version)))


def _numpy_simd() -> tuple[str, ...]:
    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # NumPy 1.x
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    return tuple(t for t in __cpu_dispatch__ if __cpu_features__.get(t))


def fingerprint() -> Platform:
    """This process's platform, read now (a few milliseconds; not cached: the thread counts
    may be changed at run time)."""
    import llvmlite.binding as llvm
    from numba.core import config
    from numba.core.codegen import get_host_cpu_features

    host = llvm.get_host_cpu_features()
    kernel_features = (config.CPU_FEATURES if config.CPU_FEATURES is not None
                       else get_host_cpu_features())
    libc = " ".join(p for p in platform.libc_ver() if p) or "unknown"
    return Platform(
        machine=platform.machine(), libc=libc,
        kernel_cpu=config.CPU_NAME or llvm.get_host_cpu_name(),
        kernel_features=",".join(sorted(f for f in kernel_features.split(",")
                                        if f.startswith("+"))),
        cpu_flags=tuple(f for f in DISPATCH_FEATURES if host.get(f)),
        numpy_simd=_numpy_simd(), blas=_blas(), numba_threads=int(config.NUMBA_NUM_THREADS),
        cpu_model=_cpu_model(), host_cpu=llvm.get_host_cpu_name(),
        thread_env={k: os.environ[k] for k in THREAD_ENV if k in os.environ},
        openblas_coretype=os.environ.get("OPENBLAS_CORETYPE", ""))


def platform_key() -> str:
    return fingerprint().key()
