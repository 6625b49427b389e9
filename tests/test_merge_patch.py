"""``extends`` as JSON Merge Patch (RFC 7386, issue 51): the RFC's own examples, a spec that
deletes what it inherits, ``{}`` that changes nothing, a claims file that deletes a run, and
``validate --explain`` naming where each key came from."""

from __future__ import annotations

import json

import pytest
from conftest import run_cli_in_process

from pipeline.claims.register import load_claims
from pipeline.merge_patch import merge_patch
from pipeline.paths import SHIPPED_SPECS
from pipeline.spec import load_spec

# RFC 7386, Appendix A: (original, patch, result), as the RFC prints them.
RFC_EXAMPLES = [
    ('{"a":"b"}', '{"a":"c"}', '{"a":"c"}'),
    ('{"a":"b"}', '{"b":"c"}', '{"a":"b","b":"c"}'),
    ('{"a":"b"}', '{"a":null}', '{}'),
    ('{"a":"b","b":"c"}', '{"a":null}', '{"b":"c"}'),
    ('{"a":["b"]}', '{"a":"c"}', '{"a":"c"}'),
    ('{"a":"c"}', '{"a":["b"]}', '{"a":["b"]}'),
    ('{"a":{"b":"c"}}', '{"a":{"b":"d","c":null}}', '{"a":{"b":"d"}}'),
    ('{"a":[{"b":"c"}]}', '{"a":[1]}', '{"a":[1]}'),
    ('["a","b"]', '["c","d"]', '["c","d"]'),
    ('{"a":"b"}', '["c"]', '["c"]'),
    ('{"a":"foo"}', 'null', 'null'),
    ('{"a":"foo"}', '"bar"', '"bar"'),
    ('{"e":null}', '{"a":1}', '{"e":null,"a":1}'),
    ('[1,2]', '{"a":"b","c":null}', '{"a":"b"}'),
    ('{}', '{"a":{"bb":{"ccc":null}}}', '{"a":{"bb":{}}}'),
]


@pytest.mark.parametrize("original, patch, result", RFC_EXAMPLES)
def test_the_rfcs_examples(original, patch, result):
    target = json.loads(original)
    assert merge_patch(target, json.loads(patch)) == json.loads(result)
    assert target == json.loads(original)  # the target is not changed in place


def test_a_spec_deletes_an_inherited_key_with_null(tmp_path):
    """A spec extending panda_nominal drops its finger locks with null; {} merges (the locks
    stay); the rest is the parent's."""
    parent = load_spec("panda_nominal")
    assert parent.robot.locked_joints  # the fingers
    (tmp_path / "unlocked.yaml").write_text(
        "extends: panda_nominal\nrobot: {locked_joints: null}\n")
    (tmp_path / "merged.yaml").write_text(
        "extends: panda_nominal\nrobot: {locked_joints: {}}\n")
    unlocked = load_spec(tmp_path / "unlocked.yaml")
    assert unlocked.robot.locked_joints == {}
    assert unlocked.robot.q_bar == parent.robot.q_bar
    assert load_spec(tmp_path / "merged.yaml").robot.locked_joints == parent.robot.locked_joints


def test_a_claims_file_deletes_an_inherited_run_and_replaces_the_claims(tmp_path):
    base = SHIPPED_SPECS / "claims_ci.yaml"
    parent = load_claims(base)
    (tmp_path / "merged.yaml").write_text(f"extends: {base}\nruns: {{panda: {{against: null}}}}\n")
    merged = load_claims(tmp_path / "merged.yaml")
    assert parent.runs["panda"].against == "panda_dt015" and merged.runs["panda"].against is None
    assert merged.runs["panda"].spec == parent.runs["panda"].spec  # merged key by key
    assert [c.id for c in merged.claims] == [c.id for c in parent.claims]  # inherited
    (tmp_path / "own.yaml").write_text(
        f"extends: {base}\nruns: {{panda_null: null}}\nclaims:\n"
        "  - {id: X1, kind: physics, statement: s, expect: hold, checks: "
        "[{metric: 'panda:theory.spectral_radius', op: lt, threshold: 1.0}]}\n")
    own = load_claims(tmp_path / "own.yaml")
    assert "panda_null" in parent.runs and "panda_null" not in own.runs
    assert [c.id for c in own.claims] == ["X1"]  # a list replaces the parent's whole


def test_validate_explain_names_each_keys_source(tmp_path):
    spec = tmp_path / "child.yaml"
    spec.write_text("extends: short_nominal\ndescription: d\nrobot: {damped_inverse: null}\n")
    r = run_cli_in_process("validate", spec, "--explain")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert "  set here: description" in lines
    inherited = {line.split(":")[0].strip(): line for line in lines
                 if line.startswith("  inherited from ")}
    assert "mission.duration" in inherited["inherited from short_nominal"]
    assert "mission.dt" in inherited["inherited from nominal"]
    assert "robot.damped_inverse" not in r.stdout.split("keys of child")[1].split(
        "deleted by")[0]
    assert "  deleted by child (null): robot.damped_inverse" in lines


def test_explain_credits_an_emptied_mapping_and_lists_only_real_deletions(tmp_path):
    """A patch that deletes every key of an inherited mapping leaves an empty mapping no
    file writes: it is the patch's; a key deleted and set again by a nearer spec is not
    listed as deleted."""
    from pipeline.spec import key_sources

    (tmp_path / "bare.yaml").write_text(
        "extends: panda_nominal\nrobot: {locked_joints: {panda_finger_joint1: null, "
        "panda_finger_joint2: null}, damped_inverse: null}\n")
    (tmp_path / "again.yaml").write_text(
        "extends: bare\nrobot: {damped_inverse: {floor: 0.03}}\n")
    sources, deleted = key_sources(tmp_path / "bare.yaml")
    assert sources["robot.locked_joints"] == "bare"
    assert set(deleted) == {"robot.locked_joints.panda_finger_joint1",
                            "robot.locked_joints.panda_finger_joint2", "robot.damped_inverse"}
    sources, deleted = key_sources(tmp_path / "again.yaml")
    assert sources["robot.damped_inverse.floor"] == "again"
    assert "robot.damped_inverse" not in deleted
