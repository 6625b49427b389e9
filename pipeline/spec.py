"""Mission specs: YAML files loaded into one validated, resolved object.

A spec is a path to a YAML file or a bare name looked up on the spec search path
(:mod:`pipeline.paths`: the user's ``BREVE_SPEC_PATH``, then the specs shipped in
``specs/``). A spec may ``extends:`` another spec by name (looked up beside it first), as a
JSON Merge Patch of it (RFC 7386, :mod:`pipeline.merge_patch`): mappings merge key by key,
``null`` deletes an inherited key, any other value replaces it. ``robot.file`` is looked
up the same way, beside the spec first. The resolved spec is hashed canonically: the same
content gives the same hash whatever the key order or the file it came from (the name and
``extends`` are not part of the content); the robot file's content is keyed by its own hash
(:mod:`pipeline.provenance`).
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    PrivateAttr,
    ValidationError,
    field_validator,
    model_validator,
)

from pipeline.errors import SpecError
from pipeline.merge_patch import deleted_keys, leaf_keys, merge_patch
from pipeline.paths import find_on_search_path, spec_search_path
from pipeline.yamlfile import read_yaml

ROBOT_SUFFIXES = (".urdf", ".xml", ".mjcf")  # URDF, or MJCF (MuJoCo's XML)
_NAME_RE = re.compile(r"^[A-Za-z0-9_.\-]+$")

Positive = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNegative = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
Fraction = Annotated[float, Field(gt=0, le=1, allow_inf_nan=False)]
PositiveInt = Annotated[int, Field(gt=0)]
# The gains of eqs. 12, 13 and 37f, in SI units: a stiffness up to GAIN_MAX, a damping from
# DAMPING_MIN to GAIN_MAX. Within them, with the robots' reduced inertias (10⁻³ to 10³) and a
# step from 10⁻⁴ to 1 s, every product the loop forms (dt·μ, M̆ + dt·D̆, the map's entries)
# and the critical step 2/μ stay finite and far from double precision's ends; 10³⁰⁸ overflowed
# the damping modes' eigenproblem, 10⁻³⁰⁰ the critical step.
GAIN_MAX = 1e6
DAMPING_MIN = 1e-6
Stiffness = Annotated[float, Field(ge=0, le=GAIN_MAX, allow_inf_nan=False)]
Damping = Annotated[float, Field(ge=DAMPING_MIN, le=GAIN_MAX, allow_inf_nan=False)]
# A seed of NumPy's SeedSequence: a non-negative integer (it refuses a negative one deep in a
# run), below 2⁶⁴.
Seed = Annotated[int, Field(ge=0, lt=2**64)]


class _Block(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


class DampedInverse(_Block):
    """Damped SVD pseudo-inverse of J⊕ (eq. 6): damping fades in below ``floor``."""

    floor: Positive = 0.02
    damping: Positive = 0.02


class BodyInertial(_Block):
    """One rigid body's inertial parameters, replacing the file's (eq. 39): the mass (kg), the
    centre of mass in the body's joint frame (m) and the rotational inertia about the centre
    of mass in the joint frame's axes, [I_xx, I_yy, I_zz, I_xy, I_xz, I_yz] (kg·m²). Checked
    physical when the robot is loaded: positive definite, and each principal moment at most
    the sum of the other two."""

    mass: Positive
    com: Annotated[list[Finite], Field(min_length=3, max_length=3)]
    inertia: Annotated[list[Finite], Field(min_length=6, max_length=6)]


# The bodies robot.inertial may set: the rigid body on the free joint (the bus and all that is
# fixed to it) and the one the camera frame is on (the arm's last body and its payload).
INERTIAL_BODIES = ("bus", "payload")


class RobotSpec(_Block):
    """The robot: a URDF or MJCF file (looked up beside the spec, then on the spec search
    path), its camera frame, q̄ and the damped inverse. ``bus_inertia_scale`` multiplies the
    rotational inertia of the rigid body on the free joint (the bus and all that is fixed to
    it) about its own CoM, its mass and CoM unchanged: the knob of the bus-inertia sweep.
    ``inertial`` replaces the file's inertial parameters of the bus or the payload (the body
    the camera frame is on) with a Monte Carlo sample's (eq. 39), before the scale."""

    file: str = "robots/seed_ur3_box.xml"
    camera_frame: str = "camera"
    # The seed robot's inspection reach (specs/nominal.yaml says why).
    q_bar: list[Finite] = Field(default=[1.328, 0.512, -1.974, -0.196, -4.683, -2.543])
    damped_inverse: DampedInverse = DampedInverse()
    bus_inertia_scale: Positive = 1.0
    # Where package:// mesh URIs of a URDF are looked for (relative: to the spec's folder), for
    # the MuJoCo cross-parse only; a mesh it does not find is not needed where its body's
    # inertia is explicit. Pinocchio's model never reads a mesh: out of the spec hash.
    package_dirs: list[str] = Field(default_factory=list)
    # Joints of the file held at a value (rad, or m for a prismatic one): a gripper's jaw, a
    # finger, a joint the mission does not use. The arm is the joints left (eq. 1); q_bar
    # gives one angle per arm joint, checked against the file when the robot is loaded.
    locked_joints: dict[str, Finite] = Field(default_factory=dict)
    inertial: dict[str, BodyInertial] = Field(default_factory=dict)

    @field_validator("inertial")
    @classmethod
    def _known_bodies(cls, v: dict[str, BodyInertial]) -> dict[str, BodyInertial]:
        unknown = sorted(set(v) - set(INERTIAL_BODIES))
        if unknown:
            raise ValueError(f"unknown body {unknown[0]!r}: use {' or '.join(INERTIAL_BODIES)}")
        return v

    @field_validator("q_bar")
    @classmethod
    def _some(cls, v: list[float]) -> list[float]:
        if not v:
            raise ValueError("needs one joint angle per arm joint, got none")
        return v


class Ramp(_Block):
    """The γ ramp's knobs (eq. 20): σ <= low → floor, σ >= high → 1."""

    low: NonNegative = 0.01
    high: Positive = 0.05
    floor: Fraction = 0.3

    @model_validator(mode="after")
    def _ordered(self) -> Ramp:
        if not self.low < self.high:
            raise ValueError(f"low ({self.low}) must be below high ({self.high})")
        return self


class SamplingDefault(_Block):
    step_size: Positive = 0.05
    num: PositiveInt = 32


class ConfigSampling(_Block):
    """Startup configuration sampler (not the runtime derate ``controller.base.conditioning``)."""

    seed: Seed = 0
    default: SamplingDefault = SamplingDefault()
    low: NonNegative = 0.01
    high: Positive = 0.05
    floor: Fraction = 0.3


class BlockGain(_Block):
    K: Stiffness
    D: Damping


class Gains(_Block):
    """Block gains K̆, D̆ (eq. 13): bus attitude, camera position, camera orientation."""

    bus: BlockGain = BlockGain(K=2.0, D=2.0)
    cam_pos: BlockGain = BlockGain(K=4.0, D=8.0)
    cam_ori: BlockGain = BlockGain(K=1.0, D=1.0)
    posture: Stiffness = 0.0


class ComGains(_Block):
    """CoM loop gains (eq. 12), per unit mass (s⁻², s⁻¹, s⁻³) and the integral bound (m·s)."""

    K: Stiffness = 0.638
    D: Damping = 1.786
    Ki: Stiffness = 0.0
    i_max: NonNegative = 1.0


class Derate(_Block):
    gain: bool = False


class BaseBlock(_Block):
    conditioning: Ramp = Ramp()
    derate: Derate = Derate()


class Limits(_Block):
    """Rate and acceleration saturations (rad/s, m/s, and per second) and the clip v_max.
    Defaults: the seed robot's (specs/nominal.yaml cites them)."""

    omega_b_rate: Positive = 0.5
    omega_b_acc: Positive = 10.00466
    nu_e_lin_rate: Positive = 0.5
    nu_e_lin_acc: Positive = 5.0
    nu_e_ang_rate: Positive = 1.0
    nu_e_ang_acc: Positive = 10.0
    v_c_rate: Positive = 0.75
    v_c_acc: Positive = 1.2755
    v_max: Positive = 50.0


class NullSpaceImpedance(_Block):
    """A redundant arm's null-space impedance (eq. 37f): the stiffness ``K`` (N·m/rad) on the
    posture error q − q̄ seen along the null-space basis Z̃, the damping ``D`` (N·m·s/rad) on
    the null-space velocity ν_n, and ν_n's rate (rad/s) and acceleration (rad/s²) bounds
    (eq. 16). Only a redundant arm (n > 6) has one; it has no default, as it sets a damping
    mode of its own (μ = eig(Λ_n⁻¹ D))."""

    K: Stiffness = 0.0
    D: Damping
    rate: Positive = 1.0
    acc: Positive = 10.0


class Controller(_Block):
    integrator: Literal["explicit", "imex"] = "explicit"
    gains: Gains = Gains()
    com: ComGains = ComGains()
    base: BaseBlock = BaseBlock()
    limits: Limits = Limits()
    null_space: NullSpaceImpedance | None = None


class Sensors(_Block):
    """What the controller's measurements add to the sampled plant's state (eq. 40): a rate
    gyro on the bus (angle random walk ``gyro_arw`` in rad/√s, a constant bias per axis drawn
    N(0, ``gyro_bias``²) in rad/s, its random walk ``gyro_bias_walk`` in rad/s/√s, quantisation
    ``gyro_lsb`` in rad/s) and joint encoders (quantisation ``encoder_lsb`` in rad, which also
    enters the joint rates taken from successive readings), drawn from ``seed``'s stream. The
    bus pose and linear velocity are measured exactly."""

    seed: Seed = 0
    gyro_arw: NonNegative = 0.0
    gyro_bias: NonNegative = 0.0
    gyro_bias_walk: NonNegative = 0.0
    gyro_lsb: NonNegative = 0.0
    encoder_lsb: NonNegative = 0.0


class Timing(_Block):
    """When a step's command reaches the plant, beyond ``delay_steps`` whole steps (eq. 41):
    the controller samples its sensors on the clock at t_k and its command reaches the plant
    at t_k + (delay_steps + δ_k) dt, δ_k = ``delay_fraction`` + ``jitter``·ξ_k with ξ_k uniform
    on [0, 1) from ``seed``'s stream (the control step's latency jitter); until then the plant
    holds the command before it. Steps: 0.3 is 30 % of dt."""

    delay_fraction: float = Field(default=0.0, ge=0.0, lt=1.0)
    jitter: float = Field(default=0.0, ge=0.0, le=1.0)
    seed: Seed = 0

    @model_validator(mode="after")
    def _within_the_step(self) -> Timing:
        # δ_k stays below one step: the plant holds two commands at most within a step.
        if self.delay_fraction + self.jitter > 1.0:
            raise ValueError(f"jitter {self.jitter:g} with delay_fraction "
                             f"{self.delay_fraction:g} reaches past the step: their sum must "
                             f"be at most 1")
        return self


class Plant(_Block):
    """What moves between two control instants (eq. 29): ``reduced``, the simulator's update
    of the closed loop in reduced coordinates (eqs. 15, 22: the commanded velocity is the next
    one), or ``sampled``, the robot's forward dynamics under the command held over the step
    (zero-order hold), in ``substeps`` RK4 steps, applied ``delay_steps`` instants late, the
    bus torque saturated at ``bus_torque_max`` (N·m, 0: unbounded)."""

    model: Literal["reduced", "sampled"] = "reduced"
    substeps: int = Field(default=8, ge=1, le=10_000)
    delay_steps: int = Field(default=0, ge=0, le=1)
    # The bus's torque actuators (N·m): the held bus torque's norm saturated to it; 0: none.
    bus_torque_max: NonNegative = 0.0
    # What the controller measures of the plant (eq. 40); None: the state itself.
    sensors: Sensors | None = None
    # The command's arrival within the step and its jitter (eq. 41); None: at the instant.
    timing: Timing | None = None

    @model_validator(mode="after")
    def _used_by_the_model(self) -> Plant:
        # The reduced update has no hold, no delay and no actuator: a field only the sampled
        # plant reads would be accepted and not simulated, and the analysis would then judge
        # a loop that never ran.
        ignored = sorted(f for f in ("substeps", "delay_steps", "bus_torque_max", "sensors",
                                      "timing")
                         if f in self.model_fields_set and self.model == "reduced"
                         and getattr(self, f) != type(self).model_fields[f].default)
        if ignored:
            raise ValueError(f"{ignored[0]} is read only by the sampled plant (model: sampled), "
                             f"not by model: reduced, which would ignore it")
        return self


class Mission(_Block):
    dt: Positive = 0.03
    duration: Positive = 60.0
    plant: Plant = Plant()
    # The bus's angular rate at the start (rad/s, bus frame): the tumble left after capture
    # or insertion, a Monte Carlo's initial-state dispersion (eq. 39). Zero: at rest.
    initial_omega_b: Annotated[list[Finite], Field(min_length=3, max_length=3)] = Field(
        default=[0.0, 0.0, 0.0])

    @model_validator(mode="after")
    def _at_least_one_step(self) -> Mission:
        # round(duration/dt) steps run: none would write an empty log marked complete.
        if round(self.duration / self.dt) < 1:
            raise ValueError(f"duration {self.duration:g} s is shorter than one step of "
                             f"dt {self.dt:g} s: the mission would run no step")
        return self


class Requirements(_Block):
    """The stability margins a review asks of every damping mode of the loop as flown
    (eq. 35). Defaults: 6 dB and 30°, the classical margins rigid-body attitude loops are held
    to (e.g. NASA GSFC-STD-1000, the Goddard "Golden Rules", rule on control-loop stability
    margins; cited from the literature, not verified against the text here), and one control
    step of further computation delay (a flight computer that misses one deadline)."""

    gain_margin_db: Finite = 6.0
    phase_margin_deg: Annotated[float, Field(ge=0, le=180, allow_inf_nan=False)] = 30.0
    delay_margin_steps: NonNegative = 1.0


class Guidance(_Block):
    """Inspection orbit of the CoM about the target and the camera's aim pattern."""

    orbit_radius: Positive = 6.0
    orbit_period: Positive = 900.0
    orbit_phase_deg: Finite = 0.0
    aim_amplitude: NonNegative = 0.5
    aim_period: Positive = 40.0


class Target(_Block):
    bus_size: list[Positive] = Field(default=[1.2, 1.2, 1.5])
    panel_span: Positive = 2.5
    panel_width: Positive = 1.0
    n_points: PositiveInt = 1500
    seed: Seed = 7

    @field_validator("bus_size")
    @classmethod
    def _three(cls, v: list[float]) -> list[float]:
        if len(v) != 3:
            raise ValueError(f"needs 3 sizes, got {len(v)}")
        return v


class Camera(_Block):
    fov_deg: Annotated[float, Field(gt=0, lt=180, allow_inf_nan=False)] = 40.0
    d_min: Positive = 0.5
    d_max: Positive = 10.0
    max_angle_deg: Annotated[float, Field(gt=0, le=90, allow_inf_nan=False)] = 75.0
    # The image's size (square, px): a stated figure, for the roll's smear in pixels (eq. 32).
    resolution_px: PositiveInt = 1024


class Spec(_Block):
    """One resolved mission spec."""

    name: str
    description: str = ""
    robot: RobotSpec = RobotSpec()
    mission: Mission = Mission()
    controller: Controller = Controller()
    guidance: Guidance = Guidance()
    target: Target = Target()
    camera: Camera = Camera()
    config_sampling: ConfigSampling = ConfigSampling()
    requirements: Requirements = Requirements()
    # The folder of the spec file (where its own files are looked up first) and the robot file
    # found from it; neither is content: the robot counts by its hash (provenance).
    _here: Path | None = PrivateAttr(default=None)
    _robot_path: Path | None = PrivateAttr(default=None)

    @property
    def robot_path(self) -> Path:
        if self._robot_path is None:
            raise SpecError(f"spec {self.name}: robot file {self.robot.file} not resolved")
        return self._robot_path

    @property
    def package_dirs(self) -> tuple[Path, ...]:
        """robot.package_dirs as folders: relative ones from the spec's folder."""
        base = self._here if self._here is not None else Path.cwd()
        return tuple(Path(d) if Path(d).is_absolute() else base / d
                     for d in self.robot.package_dirs)

    def content(self) -> dict[str, Any]:
        """The spec's content: everything but its name."""
        d = self.model_dump(mode="json")
        d.pop("name")
        d.pop("description")
        return d

    @property
    def spec_hash(self) -> str:
        return spec_hash_of(self.content())

    @property
    def n_steps(self) -> int:
        return round(self.mission.duration / self.mission.dt)


# Fields a spec carries (the precursor's config_sampling block has them, DESIGN.md) that change
# nothing a run computes: the controller's ramp is controller.base.conditioning, and these are
# only Sampling.scale_by_svd's defaults when it is called without a ramp, which no run does.
# They do not enter the spec hash, so editing them re-simulates nothing (tests/test_spec.py
# runs a mission with other values and gets the same log, bit for bit).
INERT_FIELDS = (("config_sampling", "low"), ("config_sampling", "high"),
                ("config_sampling", "floor"), ("robot", "package_dirs"))


# Fields that came after specs were hashed, and the value that means "not set": no locked
# joints, no null-space impedance (a six-joint arm), the file's inertial parameters, a bus at
# rest at the start.
UNSET_FIELDS = (("robot", "locked_joints", {}), ("controller", "null_space", None),
                ("robot", "inertial", {}), ("mission", "initial_omega_b", [0.0, 0.0, 0.0]),
                ("mission.plant", "sensors", None), ("mission.plant", "timing", None))


def hashed_content(content: dict[str, Any]) -> dict[str, Any]:
    """What the spec hash reads of a spec's content (a resolved spec as JSON): all of it but
    its name, its description, the ``INERT_FIELDS`` and the ``UNSET_FIELDS`` at their unset
    value."""
    d = {k: v for k, v in content.items() if k not in ("name", "description")}
    for block, key in INERT_FIELDS:
        if isinstance(d.get(block), dict):
            d[block] = {k: v for k, v in d[block].items() if k != key}
    # Fields added since, at their unset value, are the spec as it was before them: its hash
    # is unchanged.
    for block, key, unset in UNSET_FIELDS:
        _drop_unset(d, block.split("."), key, unset)
    return d


def spec_hash_of(content: dict[str, Any]) -> str:
    """The spec hash of a spec's content: the canonical hash of its ``hashed_content``."""
    return canonical_hash(hashed_content(content))


def spec_differences(a: dict[str, Any], b: dict[str, Any]) -> list[str]:
    """The dotted keys at which two resolved specs differ, as the spec hash reads them (a
    field a run does not depend on, or one unset, is no difference), sorted."""
    def walk(x: Any, y: Any, prefix: str) -> list[str]:
        if isinstance(x, dict) and isinstance(y, dict):
            return [k for key in sorted(set(x) | set(y))
                    for k in walk(x.get(key), y.get(key), f"{prefix}{key}.")]
        return [] if x == y else [prefix[:-1]]

    return walk(hashed_content(a), hashed_content(b), "")


def _drop_unset(d: dict, path: list[str], key: str, unset: Any) -> None:
    """Remove ``key`` from the block at ``path`` (copied on the way) when it holds ``unset``."""
    node = d.get(path[0])
    if not isinstance(node, dict):
        return
    if len(path) > 1:
        d[path[0]] = dict(node)
        _drop_unset(d[path[0]], path[1:], key, unset)
        return
    if key in node and node[key] == unset:
        d[path[0]] = {k: v for k, v in node.items() if k != key}


def canonical_hash(obj: Any) -> str:
    """SHA-256 of the canonical JSON form (sorted keys, no whitespace)."""
    text = json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


def resolve_spec_path(spec: str | Path, here: Path | None = None) -> Path:
    """A spec argument is a path to a YAML file (relative to ``here``, the folder of the file
    that names it, else to the working directory), or a bare name on the spec search path
    (beside ``here`` first)."""
    p = Path(spec).expanduser()
    if p.suffix in (".yaml", ".yml"):
        cands = [p] if p.is_absolute() or here is None else [Path(here) / p, p]
        for cand in cands:
            if cand.is_file():
                return cand
        raise SpecError(f"{p}: spec file not found")
    return _named_spec(str(spec), here, Path("spec argument"))


def _named_spec(name: str, here: Path | None, referrer: Path) -> Path:
    if not _NAME_RE.match(name) or name.startswith("."):
        raise SpecError(f"{referrer}: spec name {name!r} is not a bare name (a path must end "
                        f"in .yaml)")
    found = find_on_search_path(f"{name}.yaml", here)
    if found is None:
        where = ", ".join(str(f) for f in spec_search_path(here))
        raise SpecError(f"{referrer}: spec {name!r} not found in {where}")
    return found


def _read_yaml(path: Path) -> dict:
    return read_yaml(path, "spec")


def spec_chain(path: Path) -> list[tuple[Path, dict]]:
    """The spec file and its ``extends`` ancestors, nearest first, each with its own raw
    mapping (``extends`` taken out)."""
    chain: list[tuple[Path, dict]] = []
    path = path.resolve()
    while True:
        if any(path == p for p, _ in chain):
            cycle = " -> ".join(p.stem for p in (*(p for p, _ in chain), path))
            raise SpecError(f"{path}: cycle in extends: {cycle}")
        data = _read_yaml(path)
        parent = data.pop("extends", None)
        chain.append((path, data))
        if parent is None:
            return chain
        if not isinstance(parent, str):
            raise SpecError(f"{path}: field extends: must be a spec name")
        path = _named_spec(parent, path.parent, path).resolve()


def raw_spec(path: Path) -> dict:
    """The merged raw mapping of a spec and its ``extends`` chain: each file a JSON Merge
    Patch (RFC 7386) of its parent's (:mod:`pipeline.merge_patch`)."""
    return _merged(spec_chain(path))


def _merged(chain: list[tuple[Path, dict]]) -> dict:
    """The chain's mappings applied root first, each a merge patch of the one before."""
    merged = chain[-1][1]
    for _, data in reversed(chain[:-1]):
        merged = merge_patch(merged, data)
    return merged


def key_sources(path: Path) -> tuple[dict[str, str], dict[str, str]]:
    """({dotted key: the spec that sets it}, {dotted key: the spec whose null deleted it}) for
    every leaf of a spec's merged mapping (``validate --explain``)."""
    chain = spec_chain(path)
    own = [(p.stem, leaf_keys(data)) for p, data in chain]
    merged = leaf_keys(_merged(chain))
    sources = {}
    for key in merged:
        # A mapping whose every key a patch deleted is an empty leaf no file writes: the
        # nearest spec that touches it (or a key inside it) made it so.
        sources[key] = next((name for name, leaves in own if key in leaves), None) or next(
            name for name, leaves in own if any(k.startswith(f"{key}.") for k in leaves)
            or key in leaves)
    # A patch's nulls (not the root's, whose nulls are values), unless a nearer spec sets the
    # key again.
    deleted = {key: p.stem for p, data in reversed(chain[:-1]) for key in deleted_keys(data)
               if not any(k == key or k.startswith(f"{key}.") for k in merged)}
    return sources, deleted


def build_spec(name: str, data: dict, source: Path | str, here: Path | None = None,
               find_robot: bool = True) -> Spec:
    """Validate a raw mapping into a Spec; errors name the field and the source. Its robot
    file is looked up from ``here`` (the spec file's folder), then on the search path (unless
    ``find_robot`` is false: a log's spec finds its robot by the log's hash)."""
    try:
        spec = Spec.model_validate({**data, "name": name})
    except ValidationError as exc:
        err = exc.errors()[0]
        field = ".".join(str(x) for x in err["loc"]) or "<root>"
        msg = err["msg"]
        if err["type"] == "extra_forbidden":
            msg = "unknown key"
        raise SpecError(f"{source}: field {field}: {msg}") from None
    spec._here = here
    if find_robot:
        spec._robot_path = _find_robot(spec, source, here)
    return spec


def _find_robot(spec: Spec, source: Path | str, here: Path | None) -> Path:
    ref = spec.robot.file
    if Path(ref).suffix.lower() not in ROBOT_SUFFIXES:
        raise SpecError(f"{source}: field robot.file: {ref!r} is neither URDF nor MJCF "
                        f"(suffix one of {', '.join(ROBOT_SUFFIXES)})")
    found = find_on_search_path(ref, here)
    if found is None:
        where = ", ".join(str(f) for f in spec_search_path(here))
        raise SpecError(f"{source}: field robot.file: robot file {ref!r} not found in {where}")
    return found


def load_spec(spec: str | Path, here: Path | None = None) -> Spec:
    """Load, merge (``extends``) and validate a spec by path or name (see
    :func:`resolve_spec_path`)."""
    path = resolve_spec_path(spec, here)
    return build_spec(path.stem, raw_spec(path), path, path.resolve().parent)


def with_overrides(spec: Spec, overrides: dict[str, Any], name: str | None = None) -> Spec:
    """A copy of ``spec`` with dotted-key overrides (``mission.dt``), validated again."""
    data = spec.model_dump(mode="json")
    data.pop("name")
    for key, value in overrides.items():
        node = data
        parts = key.split(".")
        for part in parts[:-1]:
            if not isinstance(node.get(part), dict):
                raise SpecError(f"--set {key}: unknown key {part!r}")
            node = node[part]
        if parts[-1] not in node:
            raise SpecError(f"--set {key}: unknown key {parts[-1]!r}")
        node[parts[-1]] = value
    return build_spec(name or spec.name, data, f"--set on {spec.name}", spec._here)


