"""The caches of work repeated on the same input: what a cache serves is what a fresh computation gives, and another
input (a description that differs in any field, another subcommand) is never served from it."""
from __future__ import annotations

import dataclasses

from arm_model.description import Visual, load_description
from conftest import NOMINAL


def test_urdf_text_cached_equals_fresh_and_another_description_is_its_own():
    from arm_model.urdf import _urdf_text, urdf_text
    desc = load_description(NOMINAL)
    fresh = _urdf_text.__wrapped__(type(_urdf_key(desc))(desc), "base_link", "ball")
    assert urdf_text(desc) == fresh
    assert urdf_text(load_description(NOMINAL)) == fresh            # an equal description read again: the same
    assert urdf_text(desc, tip_link="tool") != fresh                 # other names: another text
    # fields == leaves out (a user's visuals) and numbers == takes as equal (-0.0, 0.0) make another text
    eye = tuple(tuple(1.0 if i == k else 0.0 for k in range(4)) for i in range(4))
    box = Visual(row=0, pose=eye, geometry='<geometry><box size="1 1 1"/></geometry>')
    visual = dataclasses.replace(desc, visuals=(box,))
    assert visual == desc and urdf_text(visual) != fresh and 'box size="1 1 1"' in urdf_text(visual)
    j = desc.joints[0]
    signed = dataclasses.replace(desc, joints=(dataclasses.replace(j, theta_offset=-0.0),) + desc.joints[1:])
    assert j.theta_offset == 0.0 and signed == desc and signed.exact_key != desc.exact_key
    assert urdf_text(signed) == _urdf_text.__wrapped__(type(_urdf_key(desc))(signed), "base_link", "ball")
    moved = dataclasses.replace(desc, joints=(dataclasses.replace(j, d=j.d + 1e-9),) + desc.joints[1:])
    assert urdf_text(moved) != fresh


def _urdf_key(desc):
    from arm_model.urdf import _Exactly
    return _Exactly(desc)


def test_the_parser_is_built_once_a_subcommand_module_and_parsing_leaves_it_unchanged(tmp_path):
    from arm_model.cli import _build, build_parser
    tip = build_parser(["tip", "x.csv"])
    assert build_parser(["urdf"]) is tip                             # tip and urdf: one module
    assert build_parser(["no-such-command"]) is not tip                # another set of modules: its own
    fresh = _build.__wrapped__(("arm_model.commands",))
    given = ["tip", "p.csv", "--arm", "aacmm7", "--tip-frame", "ball", "-o", str(tmp_path / "t.csv"), "-q"]
    assert vars(tip.parse_args(given)) == vars(fresh.parse_args(given))
    bare = ["tip", "p.csv", "--arm", "aacmm7", "-o", str(tmp_path / "t.csv")]
    after = vars(tip.parse_args(bare))                               # no option of the first parse carries over
    assert after == vars(fresh.parse_args(bare)) and after["tip_frame"] is None and not after["quiet"]
    assert tip.format_help() == fresh.format_help()
