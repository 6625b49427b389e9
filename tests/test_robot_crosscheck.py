"""The loader's cross-parse of a robot file, Pinocchio against MuJoCo (issue 22 items 1 and 5).

Both shipped robots pass; the seed file as it was before issue 22 (the camera site inside the
jointless ``payload``, tests/fixtures/seed_ur3_box_issue2534.xml) fails with its one-line
message. The two parsers read the same file, so to show that each comparison can fail the
Pinocchio model is perturbed after parsing (a mass, an inertia, a placement, an armature) or
the velocity map is given the wrong free-joint convention. A pass is cached: a second load of
the same file content compiles nothing with MuJoCo.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import run_cli, run_cli_in_process

from pipeline.errors import SpecError
from pipeline.paths import PROJECT_ROOT, SHIPPED_SPECS
from pipeline.sim import robot_crosscheck as rc
from pipeline.sim.robot_file import _parse, load_robot_model

SEED = SHIPPED_SPECS / "robots" / "seed_ur3_box.xml"
SERVICER = SHIPPED_SPECS / "robots" / "servicer_ur3.urdf"
OLD_SEED = PROJECT_ROOT / "tests" / "fixtures" / "seed_ur3_box_issue2534.xml"
ROBOTS = {"seed": SEED, "servicer": SERVICER}
KINDS = {"position", "rotation", "axis", "mass", "com", "inertia", "twist", "mass_matrix"}


@pytest.fixture
def compiles(monkeypatch, tmp_path) -> list:
    """An empty verdict cache, and the list of MuJoCo compiles made."""
    made: list = []
    real = rc.mujoco_spec

    def counted(path, *args):
        made.append(path)
        return real(path, *args)

    monkeypatch.setattr(rc, "cache_dir", lambda: tmp_path / "xcheck")
    monkeypatch.setattr(rc, "mujoco_spec", counted)
    return made


@pytest.mark.parametrize("name", ROBOTS)
def test_the_shipped_robots_agree_to_round_off(name):
    path = ROBOTS[name]
    result = rc.compare_parsers(path, _parse(path), "camera")
    assert set(result.max_diff) == KINDS and result.configurations == 1 + rc.N_RANDOM
    for kind, diff in result.max_diff.items():
        assert diff <= result.tol[kind], kind
        assert result.tol[kind] < 1e-10, kind  # round-off, not engineering
    assert len(result.joints) == 7 and "camera" in result.bodies + result.sites
    # every body MuJoCo keeps is compared (the URDF's fixed links included: fusestatic off)
    mj = rc.mujoco_model(path)
    assert sorted(result.bodies) == sorted(mj.body(b).name for b in range(1, mj.nbody))


def test_the_old_seed_file_fails_with_one_line_naming_the_camera_and_the_cause(compiles):
    with pytest.raises(SpecError) as exc:
        load_robot_model(OLD_SEED, "camera")
    msg = str(exc.value)
    assert "\n" not in msg
    assert msg.startswith(f"{OLD_SEED}: ")
    assert "site 'camera' (the camera frame)" in msg and "the neutral configuration" in msg
    assert "Pinocchio (0.4569, 0.1124, 0.0291) m" in msg  # pin 4.1.0 (issue 2534)
    assert "MuJoCo (0.4569, 0.2977, 0.1291) m" in msg  # the file's meaning
    assert "a site of a body without a joint ('payload')" in msg
    assert "pinocchio issue 2534" in msg and "declare it on the jointed body" in msg
    assert not list((rc.cache_dir()).glob("*.json"))  # a failure is not cached


def test_the_old_seed_file_is_exit_2_in_the_cli(tmp_path):
    spec = tmp_path / "old_seed.yaml"
    spec.write_text(f"extends: nominal\nrobot: {{file: {OLD_SEED}}}\n")
    r = run_cli("validate", str(spec))
    assert r.returncode == 2, r.stderr
    assert "pinocchio issue 2534" in r.stderr and "site 'camera'" in r.stderr


def _seed_model() -> pin.Model:
    return _parse(SEED)


def _perturbed(change) -> str:
    model = _seed_model()
    change(model)
    with pytest.raises(SpecError) as exc:
        rc.compare_parsers(SEED, model, "camera")
    msg = str(exc.value)
    assert "\n" not in msg and msg.startswith(f"{SEED}: Pinocchio and MuJoCo disagree on ")
    return msg


def test_a_mass_off_by_a_microgram_fails():
    def change(m):
        m.inertias[4] = pin.Inertia(m.inertias[4].mass + 1e-9, m.inertias[4].lever,
                                    m.inertias[4].inertia)
    msg = _perturbed(change)
    assert "the total mass" in msg and "likely cause" in msg


def test_an_inertia_off_in_one_entry_fails():
    def change(m):
        inertia = m.inertias[5].inertia.copy()
        inertia[2, 2] *= 1 + 1e-9
        m.inertias[5] = pin.Inertia(m.inertias[5].mass, m.inertias[5].lever, inertia)
    msg = _perturbed(change)
    assert "the world inertia about its CoM of the rigid body of joint 'wrist_1_joint'" in msg
    assert "inertial data" in msg


def test_a_joint_placement_off_by_a_nanometre_fails():
    def change(m):
        m.jointPlacements[3].translation += np.array([0.0, 1e-9, 0.0])
    msg = _perturbed(change)
    assert "the position of body 'upper_arm_link'" in msg and "kinematic tree" in msg


def test_an_armature_only_pinocchio_has_fails_on_the_mass_matrix():
    def change(m):
        m.armature[8] = 1e-6  # kg·m², the elbow's dof: placements and inertias unchanged
    msg = _perturbed(change)
    assert "the joint-space inertia matrix M (largest at [8, 8])" in msg and "armature" in msg


def test_the_free_joint_convention_is_verified_not_assumed(monkeypatch):
    """With T = I (MuJoCo's free-joint linear velocity taken as Pinocchio's, both in the
    body frame) the body twists disagree at a rotated bus pose."""
    real = rc._set_mujoco

    def wrong(p, q):
        T = real(p, q)
        T[0:3, 0:3] = np.eye(3)
        return T

    monkeypatch.setattr(rc, "_set_mujoco", wrong)
    with pytest.raises(SpecError) as exc:
        rc.compare_parsers(SEED, _seed_model(), "camera")
    msg = str(exc.value)
    assert "random configuration 1" in msg and "LOCAL twist" in msg
    assert "velocity convention" in msg


def test_a_synthetic_site_in_a_nested_jointless_body_fails(tmp_path):
    """The defect of issue 2534 in a minimal MJCF: a site inside a jointless body nested in
    another jointless body with an offset."""
    links = "".join(f'<body name="l{i}" pos="0 0 0.1"><joint name="j{i}" axis="0 0 1"/>'
                    f'<inertial pos="0 0 0.05" mass="1" diaginertia="0.01 0.01 0.01"/>'
                    for i in range(6))
    tool = ('<body name="mount" pos="0 0.1 0" euler="1.5 0 0"><body name="lens" pos="0 0 0.2">'
            '<inertial pos="0 0 0" mass="0.1" diaginertia="1e-4 1e-4 1e-4"/>'
            '<site name="camera" pos="0 0 0.05"/></body></body>')
    path = tmp_path / "nested.xml"
    path.write_text('<mujoco><worldbody><body name="bus"><freejoint/>'
                    '<inertial pos="0 0 0" mass="5" diaginertia="0.1 0.1 0.1"/>'
                    + links + tool + "</body>" * 6 + "</body></worldbody></mujoco>")
    with pytest.raises(SpecError) as exc:
        rc.compare_parsers(path, _parse(path), "camera")
    assert "site 'camera'" in str(exc.value) and "('lens')" in str(exc.value)


def test_a_pass_is_cached_by_content_and_a_warm_load_compiles_nothing(compiles):
    load_robot_model(SEED, "camera")
    load_robot_model(SERVICER, "camera")
    assert len(compiles) == 2
    load_robot_model(SEED, "camera", bus_inertia_scale=3.0)  # the check is about the file
    load_robot_model(SERVICER, "camera")
    assert len(compiles) == 2
    stored = sorted(rc.cache_dir().glob("*.json"))
    assert len(stored) == 2
    verdict = json.loads(stored[0].read_text())
    assert verdict["pin"] == pin.__version__ and set(verdict["max_diff"]) == KINDS


def test_another_content_or_a_damaged_verdict_checks_again(compiles, tmp_path):
    copy = tmp_path / "seed.xml"
    copy.write_text(SEED.read_text())
    load_robot_model(copy, "camera")
    load_robot_model(copy, "camera")
    assert len(compiles) == 1
    copy.write_text(SEED.read_text() + "<!-- edited -->\n")
    load_robot_model(copy, "camera")
    assert len(compiles) == 2
    key = rc.cache_key(copy, "camera")
    (rc.cache_dir() / f"{key}.json").write_text("{not json")
    load_robot_model(copy, "camera")
    assert len(compiles) == 3


# -- robot files as users have them: meshes (issue 33, item 4) --------------------------------

def _binary_stl(path: Path) -> None:
    """A tetrahedron of 0.1 m as a binary STL (MuJoCo reads binary STL only)."""
    import struct

    v = [(0, 0, 0), (0.1, 0, 0), (0, 0.1, 0), (0, 0, 0.1)]
    faces = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]
    data = b"tetrahedron".ljust(80, b" ") + struct.pack("<I", len(faces))
    for a, b, c in faces:
        data += struct.pack("<12fH", 0, 0, 0, *v[a], *v[b], *v[c], 0)
    path.write_bytes(data)


def _seed_with_mesh(tmp_path, explicit: bool) -> Path:
    """The seed MJCF with a mesh geom on the bus body, whose file is not there; the bus keeps
    its explicit inertial, or loses it (its inertia would then come from the mesh)."""
    text = SEED.read_text()
    text = text.replace('<option gravity="0 0 0"/>', '<option gravity="0 0 0"/>\n  <asset>'
                        '<mesh name="base" file="meshes/base.stl"/></asset>', 1)
    bus = '<inertial pos="0 0 0" quat="1 0 0 0" mass="5.0" diaginertia="0.008 0.008 0.01"/>'
    assert bus in text
    text = text.replace(bus, (bus if explicit else "") + '<geom type="mesh" mesh="base"/>', 1)
    path = tmp_path / f"seed_mesh_{explicit}.xml"
    path.write_text(text)
    return path


def test_a_missing_mesh_is_not_needed_where_the_inertia_is_explicit(compiles, tmp_path):
    path = _seed_with_mesh(tmp_path, explicit=True)
    result = rc.compare_parsers(path, _parse(path), "camera")
    assert result.notes == ["mesh meshes/base.stl missing, not needed: the inertia of "
                            "box_base is explicit"]
    seed = rc.compare_parsers(SEED, _parse(SEED), "camera")
    assert result.max_diff.keys() == seed.max_diff.keys()
    load_robot_model(path, "camera")  # the loader accepts it


def test_a_missing_mesh_is_named_on_the_terminal(tmp_path):
    """validate on a spec whose robot file has a mesh that is not there (not needed: its
    body's inertia is explicit) says so on the terminal, one warning line, as the
    cross-parse's JSON does (issue 51)."""
    path = _seed_with_mesh(tmp_path, explicit=True)
    spec = tmp_path / "meshy.yaml"
    spec.write_text(f"extends: short_nominal\nrobot: {{file: {path}}}\n")
    r = run_cli_in_process("validate", spec)
    assert r.returncode == 0, r.stderr
    lines = [x for x in r.stderr.splitlines() if x.startswith("warning:")]
    assert lines == [f"warning: {path}: mesh meshes/base.stl missing, not needed: the inertia "
                     f"of box_base is explicit"]


def test_a_missing_mesh_that_gives_a_body_its_inertia_is_refused_naming_the_body(compiles,
                                                                                 tmp_path):
    path = _seed_with_mesh(tmp_path, explicit=False)
    with pytest.raises(SpecError, match=r"body 'box_base': its inertia comes from its geoms, "
                                        r"and its mesh 'meshes/base.stl' is missing"):
        load_robot_model(path, "camera")


def test_package_uris_resolve_against_the_package_dirs_or_are_ignored_saying_so(compiles,
                                                                                tmp_path):
    """The servicer's URDF with a package:// collision mesh on a link of explicit inertia:
    without the package folder the cross-parse passes and says the mesh was not needed; with
    it, the mesh is found (a real STL here) and nothing is said."""
    text = SERVICER.read_text().replace(
        '<link name="shoulder_link">',
        '<link name="shoulder_link"><collision><geometry><mesh '
        'filename="package://ur_description/meshes/shoulder.stl"/></geometry></collision>', 1)
    path = tmp_path / "servicer_mesh.urdf"
    path.write_text(text)
    model = _parse(path)
    ignored = rc.compare_parsers(path, model, "camera")
    assert len(ignored.notes) == 1 and "shoulder.stl missing, not needed" in ignored.notes[0]
    assert "shoulder_link" in ignored.notes[0]
    pkg = tmp_path / "pkgs" / "ur_description" / "meshes"
    pkg.mkdir(parents=True)
    _binary_stl(pkg / "shoulder.stl")
    found = rc.compare_parsers(path, model, "camera", (tmp_path / "pkgs",))
    assert found.notes == []
    load_robot_model(path, "camera", package_dirs=(tmp_path / "pkgs",))
