"""A log as a labelled table, for a notebook: ``read_log_table("logs/nominal/run.parquet")``.

The log is opened through the artefact store's door (verified against its metadata, its robot
file found by hash), so a damaged or altered log is refused here as everywhere. Each vector
column is spread into one column per component, named by the robot's shape
(:meth:`pipeline.shapes.RobotShape.labels`: ``omega_b.z``, ``q.<joint>``,
``u_applied.<joint>``) with the joint names of the robot file the log was run with; scalar
columns keep their names. The index is the time ``t`` in seconds.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from pipeline.errors import LogError
from pipeline.sim.robot_file import load_spec_robot, robot_shape
from pipeline.store.door import ArtefactStore


def read_log_table(path: Path | str) -> pd.DataFrame:
    """The log at ``path`` (simulated or imported) as a DataFrame indexed by ``t``, one column
    per scalar and per component of each vector (eq. 1's blocks, by name). A LogError (exit 2)
    or LogDamaged (exit 1) naming the file when it cannot be trusted."""
    path = Path(path)
    log = ArtefactStore(path.parent.parent).open_log(path)
    shape = robot_shape(load_spec_robot(log.spec))
    names = log.column_names()
    data = log.columns(names)
    out: dict[str, np.ndarray] = {}
    for name in names:
        values = data[name]
        if values.ndim == 1:
            out[name] = values
            continue
        labels = shape.labels(name)
        if len(labels) != values.shape[1]:
            raise LogError(f"{path}: column {name}: {values.shape[1]} components, its robot "
                           f"file's shape has {len(labels)}")
        out.update(zip(labels, values.T, strict=True))
    table = pd.DataFrame(out)
    return table.set_index("t") if "t" in table else table
