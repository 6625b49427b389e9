"""The one door to the artefacts (pipeline/store/door.py): a log verified and hashed once per
store, reuse only of what was made from these bytes, a comparison only of one robot, and the
verified bytes read even when the path is replaced."""

from __future__ import annotations

import hashlib
import os
from dataclasses import replace

import pytest

from pipeline.errors import SpecError
from pipeline.logs import read_columns
from pipeline.spec import load_spec, with_overrides
from pipeline.store import door
from pipeline.store.door import ArtefactStore


def _spec(name: str, base: str = "short_nominal", **overrides):
    return with_overrides(load_spec(base), {"mission.duration": 0.6, **overrides}, name=name)


@pytest.fixture
def counted(monkeypatch):
    """How often the door verifies a log (by file name of its folder)."""
    calls: list[str] = []
    real = door.verify_log

    def verify(path, *args, **kwargs):
        calls.append(path.parent.name)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(door, "verify_log", verify)
    return calls


def test_a_log_is_verified_and_hashed_once_per_store(tmp_path, counted):
    store = ArtefactStore(tmp_path)
    run = store.run(_spec("a"), quiet=True)
    assert not run.reused and counted == ["a"]
    again = store.run(_spec("a"), quiet=True)
    assert again.reused and again.log is run.log and counted == ["a"]
    assert run.log.sha256 == hashlib.sha256(run.path.read_bytes()).hexdigest()
    # a new store (a new command) verifies it again, once
    ArtefactStore(tmp_path).run(_spec("a"), quiet=True)
    assert counted == ["a", "a"]


def test_an_analysis_is_reused_only_for_the_bytes_it_was_made_from(tmp_path):
    store = ArtefactStore(tmp_path)
    log = store.run(_spec("a"), quiet=True).log
    assert not store.analysis(log, quiet=True).reused
    assert ArtefactStore(tmp_path).analysis(log, quiet=True).reused
    # run again (forced): the simulation is deterministic, the bytes are the same, the
    # analysis stays current
    other = ArtefactStore(tmp_path)
    rerun = other.run(_spec("a"), force=True, quiet=True).log
    assert rerun.sha256 == log.sha256 and other.analysis(rerun, quiet=True).reused
    # another run of the same name's bytes where the analysed log was: it verifies whole, its
    # record is there, but it is not what was analysed
    b = ArtefactStore(tmp_path / "x").run(_spec("a", **{"mission.duration": 0.9}),
                                          quiet=True).log
    os.replace(b.path, log.path)
    assert (tmp_path / "a" / "analysis.json").is_file()
    moved = ArtefactStore(tmp_path).open_log(log.path)
    assert moved.sha256 != log.sha256
    assert ArtefactStore(tmp_path).current_analysis(moved) is None
    assert not ArtefactStore(tmp_path).analysis(moved, quiet=True).reused


def test_a_comparison_of_two_robots_is_refused_by_the_door(tmp_path):
    store = ArtefactStore(tmp_path)
    seed = store.run(_spec("seed"), quiet=True).log
    heavy = store.run(_spec("heavy", **{"robot.bus_inertia_scale": 2.0}), quiet=True).log
    with pytest.raises(SpecError, match="a run of another robot"):
        store.analysis(seed, heavy, quiet=True)
    assert not (tmp_path / "seed" / "analysis.json").exists()


def test_a_verified_log_reads_the_bytes_it_verified_even_if_the_path_is_replaced(tmp_path):
    store = ArtefactStore(tmp_path)
    a = store.run(_spec("a"), quiet=True).log
    b = store.run(_spec("b", **{"mission.dt": 0.01}), quiet=True).log
    t_a = read_columns(a.path, ["t"])["t"]
    os.replace(b.path, a.path)
    assert (a.columns(["t"])["t"] == t_a).all()
    assert not (read_columns(a.path, ["t"])["t"].shape == t_a.shape
                and (read_columns(a.path, ["t"])["t"] == t_a).all())


def test_the_recorded_log_is_none_when_the_bytes_are_not_the_analysed_ones(tmp_path):
    store = ArtefactStore(tmp_path)
    log = store.run(_spec("a"), quiet=True).log
    record = store.analysis(log, quiet=True).record
    assert ArtefactStore(tmp_path).recorded_log(record).sha256 == log.sha256
    assert ArtefactStore(tmp_path).recorded_log(replace(record, log_sha256="0" * 64)) is None
    assert ArtefactStore(tmp_path).recorded_log(replace(record, log=str(tmp_path / "no"))) is None


def test_a_refused_analysis_leaves_no_folder(tmp_path):
    """The lock's folder is removed when nothing was written in it."""
    logs, out = tmp_path / "logs", tmp_path / "out"
    store = ArtefactStore(logs, out)
    log = store.run(_spec("a"), quiet=True).log
    with pytest.raises(Exception, match="window"):
        store.analysis(log, window_start=1e9, quiet=True)
    assert not out.exists()


def test_a_record_of_another_window_is_not_the_default_analysis(tmp_path):
    """``analyze --window-start`` writes a record of its window; the default analysis of the
    same log is then made again, never reused from it."""
    store = ArtefactStore(tmp_path)
    log = store.run(_spec("a"), quiet=True).log
    chosen = store.analysis(log, window_start=0.1, quiet=True)
    assert not chosen.reused
    assert chosen.record.window.start_step == round(0.1 / log.spec.mission.dt)
    again = ArtefactStore(tmp_path).analysis(log, quiet=True)
    assert not again.reused and again.record.window.start_step == log.rows // 2
    assert ArtefactStore(tmp_path).analysis(log, quiet=True).reused


def test_a_verified_log_sent_to_another_process_reads_only_the_bytes_verified(tmp_path):
    """A report's figure workers get the log pickled, without its open file: the first read
    there hashes the file again and refuses one that changed since the verification."""
    import pickle

    from pipeline.errors import LogDamaged

    store = ArtefactStore(tmp_path)
    a = store.run(_spec("a"), quiet=True).log
    copy = pickle.loads(pickle.dumps(a))
    assert (copy.columns(["t"])["t"] == a.columns(["t"])["t"]).all()
    b = store.run(_spec("b", **{"mission.dt": 0.01}), quiet=True).log
    stale = pickle.loads(pickle.dumps(a))
    os.replace(b.path, a.path)
    with pytest.raises(LogDamaged, match="changed after it was verified"):
        stale.columns(["t"])


def test_the_door_hands_out_only_a_file_that_is_current(tmp_path, monkeypatch):
    """Reuse is decided again on the file that was verified: another spec's log put in place
    after the footer was read is not handed out as this spec's."""
    store = ArtefactStore(tmp_path)
    a = store.run(_spec("a"), quiet=True).log
    other = ArtefactStore(tmp_path / "x").run(_spec("a", **{"mission.duration": 0.9}),
                                              quiet=True).log
    footer_then = a.meta
    os.replace(other.path, a.path)
    monkeypatch.setattr(door, "current_log", lambda *args: footer_then)  # read before
    assert ArtefactStore(tmp_path).current_run(_spec("a")) is None


def test_a_comparison_over_another_window_of_the_second_run_is_not_reused(tmp_path):
    store = ArtefactStore(tmp_path)
    a = store.run(_spec("a"), quiet=True).log  # 20 steps: the default window starts at 10
    b = store.run(_spec("b", **{"mission.duration": 1.2}), quiet=True).log  # 40: at 20
    start = 10 * a.spec.mission.dt  # a's default start, not b's
    chosen = store.analysis(a, b, window_start=start, quiet=True)
    assert chosen.record.window.start_step == a.rows // 2
    assert chosen.record.comparison.other.window.start_step != b.rows // 2
    assert not ArtefactStore(tmp_path).analysis(a, b, quiet=True).reused
    assert ArtefactStore(tmp_path).analysis(a, b, quiet=True).reused


def test_a_log_whose_data_does_not_decode_is_damaged_and_made_again(tmp_path):
    from pipeline.errors import LogDamaged
    from pipeline.logs import verify_log

    store = ArtefactStore(tmp_path)
    log = store.run(_spec("a"), quiet=True).log
    good = log.path.read_bytes()
    data = bytearray(good)
    for frac in (0.2, 0.35, 0.5):  # data pages, well before the footer
        i = int(len(data) * frac)
        data[i:i + 64] = bytes(64)
    log.path.write_bytes(bytes(data))
    with pytest.raises(LogDamaged, match="tampered or damaged"):
        verify_log(log.path)
    again = ArtefactStore(tmp_path).run(_spec("a"), quiet=True)
    assert not again.reused and again.path.read_bytes() == good
