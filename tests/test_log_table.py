"""The public reader: a log as a labelled table, its labels from the robot file's joints.

The expected values are read from the Parquet file by pyarrow and placed by Pinocchio's
free-flyer convention written out here (q = [p_b; quat x y z w; joints], v = [v_b; ω_b; q̇],
eq. 1); the joint names are read from the MJCF by ElementTree, not by Pinocchio.
"""

from __future__ import annotations

import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pyarrow.parquet as pq
import pytest

from pipeline.errors import LogDamaged
from pipeline.paths import SHIPPED_SPECS
from pipeline.store.table import read_log_table

SEED = SHIPPED_SPECS / "robots" / "seed_ur3_box.xml"


def _mjcf_joints(path) -> list[str]:
    return [j.get("name") for j in ET.parse(path).getroot().iter("joint")]


def test_columns_are_labelled_by_the_robot_files_joints(short_logs):
    path = short_logs["short_nominal"]
    table = read_log_table(path)
    raw = pq.read_table(path)
    q = np.array(raw.column("q").to_pylist())
    v = np.array(raw.column("v").to_pylist())
    u = np.array(raw.column("u_applied").to_pylist())
    joints = _mjcf_joints(SEED)
    assert len(joints) == 6
    np.testing.assert_array_equal(table.index.to_numpy(), raw.column("t").to_numpy())
    np.testing.assert_array_equal(table["omega_b.z"], v[:, 5])
    np.testing.assert_array_equal(table["quat_tb.w"], q[:, 6])
    for i, joint in enumerate(joints):
        np.testing.assert_array_equal(table[f"q.{joint}"], q[:, 7 + i])
        np.testing.assert_array_equal(table[f"qdot.{joint}"], v[:, 6 + i])
        np.testing.assert_array_equal(table[f"u_applied.{joint}"], u[:, 6 + i])
    np.testing.assert_array_equal(table["u_applied.tau_b.z"], u[:, 5])
    vb = np.array(raw.column("v_breve").to_pylist())
    np.testing.assert_array_equal(table["v_breve.nu_e_ang.x"], vb[:, 6])
    # Every number of the file is in the table once: the scalars and each component.
    widths = sum(np.array(raw.column(c).to_pylist()).reshape(len(raw), -1).shape[1]
                 for c in raw.column_names if c != "t")
    assert table.shape == (len(raw), widths)


def test_a_damaged_log_is_refused(short_logs, tmp_path):
    path = tmp_path / "short_nominal" / "run.parquet"
    path.parent.mkdir()
    shutil.copy(short_logs["short_nominal"], path)
    data = bytearray(path.read_bytes())
    i = int(len(data) * 0.3)
    data[i:i + 64] = bytes(64)
    path.write_bytes(bytes(data))
    with pytest.raises(LogDamaged):
        read_log_table(path)
