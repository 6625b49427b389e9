"""The platform fingerprint (pipeline/platform.py): what it records, what its key decides on,
and that every log carries it (issue 21, item 1)."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from conftest import footer_metadata

from pipeline.logs import read_meta
from pipeline.paths import PROJECT_ROOT
from pipeline.platform import KEY_FIELDS, Platform, describe, differences, fingerprint
from pipeline.sim.run import run_spec
from pipeline.spec import load_spec, with_overrides


@pytest.fixture(scope="module")
def here() -> Platform:
    return fingerprint()


def test_the_fingerprint_records_the_kernel_target_the_blas_kernels_and_the_threads(here):
    assert here.machine and here.libc and here.kernel_cpu
    # NumPy's and SciPy's OpenBLAS, both loaded by fingerprint() itself.
    assert len(here.blas) >= 2 and all(b.architecture and b.num_threads >= 1 for b in here.blas)
    assert here.numba_threads >= 1
    assert set(KEY_FIELDS) < {f.name for f in dataclasses.fields(Platform)}
    assert fingerprint().key() == here.key()  # stable within a process
    assert len(here.key()) == 16 and here.kernel_cpu in here.summary()


def test_the_key_moves_with_what_decides_the_bits_and_only_with_it(here):
    # Values other than this machine's, whichever processor runs the test.
    blas = tuple(dataclasses.replace(b, architecture=f"not-{b.architecture}") for b in here.blas)
    threads = tuple(dataclasses.replace(b, num_threads=b.num_threads + 1) for b in here.blas)
    for changed in (dataclasses.replace(here, blas=blas),
                    dataclasses.replace(here, blas=threads),
                    dataclasses.replace(here, kernel_cpu=f"not-{here.kernel_cpu}"),
                    dataclasses.replace(here, cpu_flags=(*here.cpu_flags, "not-a-flag")),
                    dataclasses.replace(here, numba_threads=here.numba_threads + 1),
                    dataclasses.replace(here, libc="glibc 2.17")):
        assert changed.key() != here.key() and differences(here, changed)
    for informative in (dataclasses.replace(here, cpu_model="another CPU"),
                        dataclasses.replace(here, thread_env={"OMP_NUM_THREADS": "1"}),
                        dataclasses.replace(here,
                                            openblas_coretype=f"not-{here.openblas_coretype}")):
        assert informative.key() == here.key() and not differences(here, informative)


def test_the_record_round_trips_through_json_and_refuses_another_shape(here):
    assert Platform.from_dict(json.loads(json.dumps(here.to_dict()))) == here
    with pytest.raises(KeyError):
        Platform.from_dict({**here.to_dict(), "extra": 1})
    assert describe(None).startswith("an unknown platform")
    assert describe({"machine": "x86_64"}) == "an unreadable platform record"


def test_a_forced_openblas_kernel_is_another_platform(here):
    """OPENBLAS_CORETYPE (Sandybridge runs on any AVX CPU) changes the BLAS kernel: another
    key, and the forcing variable recorded."""
    if "avx" not in here.cpu_flags:
        pytest.skip("this CPU has no AVX: OpenBLAS's Sandybridge kernel does not run")
    code = ("import json; from pipeline.platform import fingerprint; p = fingerprint(); "
            "print(json.dumps(p.to_dict()))")
    r = subprocess.run([sys.executable, "-c", code], cwd=PROJECT_ROOT, capture_output=True,
                       text=True, timeout=120,
                       env=dict(os.environ, OPENBLAS_CORETYPE="Sandybridge"))
    assert r.returncode == 0, r.stderr
    there = Platform.from_dict(json.loads(r.stdout))
    assert there.openblas_coretype == "Sandybridge"
    assert {b.architecture for b in there.blas} == {"Sandybridge"}
    if {b.architecture for b in here.blas} != {"Sandybridge"}:
        assert there.key() != here.key() and differences(here, there) == ["blas"]


@pytest.fixture(scope="module")
def log(tmp_path_factory) -> Path:
    spec = with_overrides(load_spec("baseline_imex"), {"mission.duration": 0.3}, name="p1")
    return run_spec(spec, tmp_path_factory.mktemp("platform")).path


def test_every_log_records_its_platform_beside_the_versions(log, here):
    meta = read_meta(log)
    assert meta.versions and meta.platform is not None
    assert Platform.from_dict(meta.platform).key() == here.key()


def test_a_log_without_a_platform_still_reads_as_an_unknown_platform(log, tmp_path):
    """The pins made before logs recorded a platform."""
    md = {k: v for k, v in footer_metadata(log).items() if k != b"pipeline.platform"}
    old = tmp_path / "old" / "run.parquet"
    old.parent.mkdir()
    pq.write_table(pq.read_table(log).replace_schema_metadata(md), old)
    meta = read_meta(old)
    assert meta.platform is None and meta.versions == read_meta(log).versions
