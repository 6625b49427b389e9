"""How often one reused analysis opens Parquet files and hashes files (issue 24's measure).

Run from the repository after ``make all``: ``.venv/bin/python scripts/count_artefact_reads.py``.
It makes sure the nominal and dt010 logs and the nominal analysis (against dt010) are current,
then counts, for ``ensure_run`` and ``ensure_analysis`` of the nominal run reusing them, the
calls of pyarrow's Parquet readers and of ``file_digest`` (by file name).
"""

from __future__ import annotations

import collections
import sys

import pyarrow.parquet as pq

import pipeline.provenance.keys as keys
from pipeline.orchestrate import ensure_analysis, ensure_run
from pipeline.spec import load_spec

COUNTS: collections.Counter = collections.Counter()


def _counting(name, original):
    def wrapper(*args, **kwargs):
        COUNTS[name] += 1
        return original(*args, **kwargs)
    return wrapper


def main() -> None:
    for name in ("ParquetFile", "read_table", "read_metadata", "read_schema"):
        setattr(pq, name, _counting(name, getattr(pq, name)))
    digest = keys.file_digest

    def counted_digest(path):
        COUNTS[f"file_digest {str(path).rsplit('/', 1)[-1]}"] += 1
        return digest(path)

    # Every module that imported it by name, not only its home.
    for module in list(sys.modules.values()):
        if getattr(module, "__name__", "").startswith("pipeline") and getattr(
                module, "file_digest", None) is digest:
            module.file_digest = counted_digest
    against = ensure_run(load_spec("omega_ripple_dt010"), "logs")
    run = ensure_run(load_spec("nominal"), "logs")
    ensure_analysis(run, "generated_reports", against)  # made here if it was not current
    COUNTS.clear()
    run = ensure_run(load_spec("nominal"), "logs")
    ensure_analysis(run, "generated_reports", against)
    for name, n in sorted(COUNTS.items()):
        print(f"{name}: {n}")


if __name__ == "__main__":
    main()
