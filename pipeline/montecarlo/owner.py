"""Which study file a study's folders belong to (issue 49).

A Monte Carlo's or a power study's outputs are kept under its file's name: the kept records in
``<logs>/<name>/``, the table and the verdict in ``<out>/<name>/``. Two different files of one
name (``a/seed.yaml`` and ``b/seed.yaml``, other dispersions) would share them, the second
silently replacing the first's verdict and records. So each folder names the file that owns
it (:data:`OWNER_FILE`: the file's resolved path), and a study that would take a folder
another file owns is refused in one line before anything runs, unless ``--force``, which
gives them to this file: its table and verdict then replace the other's, and its samples'
records replace those of the same names (the rest stay, keyed by their content, never read
for this file). A folder whose owner file is gone (a checkout moved or renamed) is taken
over, and said so. The same file edited keeps its folders: its results are superseded by
their key, as before.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from pathlib import Path

from pipeline.atomic_files import atomic_write_text
from pipeline.errors import SpecError
from pipeline.paths import display_path

OWNER_FILE = ".study_file"  # in each of a study's folders: the owning file's resolved path


def check_start(kind: str, name: str, file: Path, folders: tuple[Path, ...], options,
                seconds: float, samples: list[str], force: bool) -> None:
    """What a study command checks before it starts a cluster (SpecError, exit 2, one line):
    the workers it asks for (``options``, a ``ClusterOptions``), its samples' ``seconds`` on
    them within the time budget (not judged on an existing scheduler's workers, its own), the
    samples' record paths under the first folder, and that no other file owns ``folders``."""
    from pipeline.budget import check_study_time
    from pipeline.sweep.cluster import check_workers, scheduler_address

    address = scheduler_address(options.scheduler)
    check_workers(options, address)
    if not address:
        check_study_time(seconds, len(samples), options.workers, f"{kind} {name}")
    check_record_paths(kind, name, folders[0], samples)
    check_owners(kind, name, file, folders, force)


def check_record_paths(kind: str, name: str, root: Path, samples: Iterable[str]) -> None:
    """SpecError naming the first of the samples' kept-record paths under ``root`` that is
    there but is not a file (a folder, a device): a record could not be kept there, and every
    flight into it would be lost."""
    from pipeline.montecarlo.task import record_path

    for sample in samples:
        path = record_path(root, sample)
        if path.exists() and not path.is_file():
            raise SpecError(f"{kind} {name}: {display_path(path)}: not a file, where the "
                            "sample's record is kept; move it away")


def owner(folder: Path) -> str | None:
    """The resolved path of the file that owns ``folder`` (None: no owner recorded)."""
    try:
        return (Path(folder) / OWNER_FILE).read_text().strip() or None
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"{display_path(Path(folder) / OWNER_FILE)}: unreadable ({exc})"
                        ) from None


def check_owners(kind: str, name: str, file: Path, folders: Iterable[Path],
                 force: bool = False) -> list[tuple[Path, str]]:
    """The folders another file owns, with their owners; a SpecError (exit 2) naming the
    first and its owner unless ``force`` or that owner file is gone. Reads only: a command
    checks this before it starts anything, and claims the folders (:func:`claim_folders`)
    once it can run."""
    me = str(Path(file).resolve())
    taken = [(f, o) for f in map(Path, folders) if (o := owner(f)) is not None and o != me]
    held = [(f, o) for f, o in taken if Path(o).is_file()]
    if held and not force:
        folder, other = held[0]
        raise SpecError(f"{kind} {name}: {display_path(folder)} holds the results of another "
                        f"{kind} file of that name, {other}; give this file another name, "
                        "another --logs and --out, or pass --force to replace them")
    return taken


def claim_folders(kind: str, name: str, file: Path, folders: Iterable[Path],
                  force: bool = False) -> None:
    """Make ``folders`` the study file ``file``'s (:func:`check_owners` first). Nothing is
    removed: this file's results replace the other's as they are written."""
    me = str(Path(file).resolve())
    folders = [Path(f) for f in folders]
    for folder, other in check_owners(kind, name, file, folders, force):
        gone = "" if Path(other).is_file() else " (no longer there)"
        print(f"{kind} {name}: {display_path(folder)} was {other}'s{gone}; now {me}'s",
              file=sys.stderr)
    for folder in folders:
        if owner(folder) != me:
            folder.mkdir(parents=True, exist_ok=True)
            atomic_write_text(folder / OWNER_FILE, me + "\n")
