"""How often one reused analysis opens Parquet files and hashes files (issue 24's measure).

Run from the repository after ``make all``: ``.venv/bin/python scripts/count_artefact_reads.py``.
It makes sure the nominal and dt010 logs and the nominal analysis (against dt010) are current,
then counts, for one command (a fresh artefact store) that has the dt010 log and then reuses
the nominal log and its analysis against dt010, the calls of pyarrow's Parquet readers, of
the log verification and of the file hashes (by file name), after the dt010 log is had
(``reuse``) and over the whole command (``command``).
"""

from __future__ import annotations

import collections
import sys

import pyarrow.parquet as pq

import pipeline.logs as logs
import pipeline.provenance.keys as keys
from pipeline.spec import load_spec
from pipeline.store.door import ArtefactStore

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
    verify = logs.verify_log

    def counted_verify(path, *args, **kwargs):
        COUNTS[f"verify_log {str(path).rsplit('/', 2)[-2]}"] += 1
        return verify(path, *args, **kwargs)

    def counted_digest(path):
        COUNTS[f"file_digest {str(path).rsplit('/', 1)[-1]}"] += 1
        return digest(path)

    # Every module that imported them by name, not only their home; and the default argument
    # of the verification, bound when it was defined.
    logs.verify_log.__defaults__ = (counted_digest,)
    for module in list(sys.modules.values()):
        if not getattr(module, "__name__", "").startswith("pipeline"):
            continue
        if getattr(module, "file_digest", None) is digest:
            module.file_digest = counted_digest
        if getattr(module, "verify_log", None) is verify:
            module.verify_log = counted_verify
    nominal, dt010 = load_spec("nominal"), load_spec("omega_ripple_dt010")
    store = ArtefactStore("logs", "generated_reports")
    store.analysis(store.run(nominal).log, store.run(dt010).log)  # made if it was not current
    COUNTS.clear()
    store = ArtefactStore("logs", "generated_reports")  # a new command
    against = store.run(dt010)
    whole = dict(COUNTS)
    COUNTS.clear()
    store.analysis(store.run(nominal).log, against.log)
    for name in sorted(set(COUNTS) | set(whole)):
        print(f"{name}: reuse {COUNTS[name]}, command {COUNTS[name] + whole.get(name, 0)}")


if __name__ == "__main__":
    main()
