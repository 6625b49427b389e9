"""What a foreign log holds and in which conventions: the import's mapping (a small YAML file,
each field also an option of ``python -m pipeline import``).

    format: npz              # csv | parquet | npz | rosbag | mcap (default: from the suffix)
    robot: nominal           # a spec (name or file) whose robot block is used, or the block
    time: t                  # the time stamps' column or key; or `dt:` for a log without one
    time_unit: s             # s | ms | us | ns
    max_jitter: 0            # stamps' jitter allowed beyond their resolution, × dt (< 0.25)
    q: q                     # one vector column/key (13 wide), a selection of columns
                             # ("states.x[:, 0:13]", pipeline/importer/selection.py), or a
                             # list of 13 scalar columns
    v: v                     # likewise, 12 wide
    s_min_G: sigma           # the source's own σ_min(Γ) column, if it logged one (default:
                             # none: the σ columns are rebuilt from q, and the provenance
                             # check, which would compare q with itself, is not applicable)
    quaternion: xyzw         # xyzw | wxyz
    velocity_frame: bus      # bus | world
    linear_velocity: origin  # origin | bus_com
    angle_unit: rad          # rad | deg (joint angles and rates, the bus angular velocity)
    length_unit: m           # m | mm
    topics: {odometry: /bus/odom, joints: /arm/joint_states}   # bags: nav_msgs/Odometry and
                                                              # sensor_msgs/JointState; and
                             # imu: /imu (ω_b), tf: /tf with tf_parent, tf_child (the pose)

A key or column path may go into a pickled object (``states.x``: the npz key ``states``, then
its ``x``); loading a pickle runs code from the file, so it is read only with
``allow_pickle: true`` (``--allow-pickle``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from pipeline.errors import SpecError
from pipeline.importer.conventions import Conventions
from pipeline.spec import RobotSpec, Spec, build_spec, load_spec
from pipeline.yamlfile import read_yaml

FORMATS = ("csv", "parquet", "npz", "rosbag", "mcap")
SUFFIX_FORMAT = {".csv": "csv", ".parquet": "parquet", ".npz": "npz", ".mcap": "mcap",
                 ".db3": "rosbag"}
TIME_UNITS = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}


class Topics(BaseModel):
    """A bag's topics: the bus's pose and twist from one nav_msgs/Odometry, unless its pose
    comes from TF (``tf`` with the transform ``tf_parent`` → ``tf_child``) or its angular rate
    from an IMU (``imu``: sensor_msgs/Imu, its angular velocity in the bus frame); the arm's
    from sensor_msgs/JointState."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    odometry: str = Field(min_length=1)  # nav_msgs/Odometry: the bus pose and twist
    joints: str = Field(min_length=1)  # sensor_msgs/JointState: the arm's angles and rates
    imu: str | None = Field(default=None, min_length=1)  # sensor_msgs/Imu: ω_b
    tf: str | None = Field(default=None, min_length=1)  # tf2_msgs/TFMessage: the bus pose
    tf_parent: str | None = Field(default=None, min_length=1)  # its world frame id
    tf_child: str | None = Field(default=None, min_length=1)  # its bus frame id

    @model_validator(mode="after")
    def _tf_frames(self) -> Topics:
        if self.tf is not None and (self.tf_parent is None or self.tf_child is None):
            raise ValueError("tf needs tf_parent and tf_child (the world and bus frame ids)")
        return self


class ImportMapping(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)

    format: Literal["csv", "parquet", "npz", "rosbag", "mcap"] | None = None
    robot: str | RobotSpec | None = None
    time: str | None = "t"
    time_unit: Literal["s", "ms", "us", "ns"] = "s"
    dt: float | None = Field(default=None, gt=0, allow_inf_nan=False)
    # The stamps' jitter allowed beyond their resolution, a fraction of the step (below 0.25):
    # a telemetry stamped as published is analysed at its own instants, never resampled.
    max_jitter: float = Field(default=0.0, ge=0, lt=0.25)
    q: str | list[str] = "q"
    v: str | list[str] = "v"
    s_min_G: str | None = None
    quaternion: Literal["xyzw", "wxyz"] = "xyzw"
    velocity_frame: Literal["bus", "world"] = "bus"
    linear_velocity: Literal["origin", "bus_com"] = "origin"
    angle_unit: Literal["rad", "deg"] = "rad"
    length_unit: Literal["m", "mm"] = "m"
    topics: Topics | None = None
    allow_pickle: bool = False

    @property
    def conventions(self) -> Conventions:
        return Conventions(self.quaternion, self.velocity_frame, self.linear_velocity,
                           self.angle_unit, self.length_unit)

    def source_format(self, source: Path) -> str:
        if self.format is not None:
            return self.format
        if source.is_dir() and ((source / "metadata.yaml").is_file()
                                or any(source.glob("*.db3"))):  # a ROS 2 bag is a folder
            return "rosbag"
        fmt = SUFFIX_FORMAT.get(source.suffix.lower())
        if fmt is None:
            raise SpecError(f"{source}: format: cannot tell from the suffix {source.suffix!r} "
                            f"(give --format, one of {', '.join(FORMATS)})")
        return fmt

    def record(self) -> dict[str, Any]:
        """The mapping as the imported log's metadata records it (JSON)."""
        return self.model_dump(mode="json", exclude={"allow_pickle"})


def load_mapping(path: Path | None, overrides: dict[str, Any]) -> ImportMapping:
    """The mapping file (if any) with the options given on the command line over it (each key
    given, a None included: ``--time none``); a one-line SpecError naming the file and the
    field otherwise."""
    data = read_yaml(path, "import mapping") if path is not None else {}
    data = {**data, **overrides}
    try:
        return ImportMapping.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        field = ".".join(str(x) for x in err["loc"]) or "<root>"
        msg = "unknown key" if err["type"] == "extra_forbidden" else err["msg"]
        raise SpecError(f"{path or 'import options'}: field {field}: {msg}") from None


def robot_block(mapping: ImportMapping, here: Path | None) -> tuple[RobotSpec, str, Path | None]:
    """The robot the log is of: a spec's robot block (and that spec's folder, where its robot
    file is looked for), or the mapping's own block."""
    if mapping.robot is None:
        raise SpecError("import: field robot: which robot the log is of is needed (--robot "
                        "SPEC: a spec whose robot block is used, or a robot block in the "
                        "mapping)")
    if isinstance(mapping.robot, RobotSpec):
        return mapping.robot, "the mapping's robot block", here
    spec = load_spec(mapping.robot, here)
    return spec.robot, f"spec {spec.name}", spec._here


def import_spec(name: str, robot: RobotSpec, dt: float, rows: int, here: Path | None,
                source: str) -> tuple[Spec, dict]:
    """The imported log's spec: its robot and its step, nothing of a controller."""
    content = {"robot": robot.model_dump(mode="json"),
               "mission": {"dt": dt, "duration": rows * dt}}
    return build_spec(name, content, source, here), content
