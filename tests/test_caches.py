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


def test_the_nuisance_jacobian_kept_pattern_gives_scipys_matrix_and_another_pattern_is_built_anew():
    import numpy as np
    import scipy.sparse as sp

    from calibration.problem import _TripletsCsr
    rng = np.random.default_rng(3)
    rows = np.repeat(np.arange(40), 3)
    cols = (rng.integers(0, 10, 40)[:, None] * 3 + np.arange(3)).reshape(-1)[::-1].copy()   # not in order

    def same(a, b):
        return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("data", "indices", "indptr")) \
            and a.shape == b.shape and a.indices.dtype == b.indices.dtype

    make = _TripletsCsr()
    for k in range(3):                 # the first call builds and keeps the pattern, the next ones reuse it
        v = rng.standard_normal(len(rows))
        v[k] = 0.0                     # an explicit zero stays, as in scipy's
        assert same(make(rows, cols, v, (40, 30)), sp.csr_matrix((v, (rows, cols)), shape=(40, 30)))
    assert make._kept is not None
    moved = cols.copy()
    moved[0] = (moved[0] + 1) % 30
    v = rng.standard_normal(len(rows))
    assert same(make(rows, moved, v, (40, 30)), sp.csr_matrix((v, (rows, moved)), shape=(40, 30)))
    assert same(make(rows, moved, v, (41, 30)), sp.csr_matrix((v, (rows, moved)), shape=(41, 30)))
    twice = np.concatenate([rows, rows[:1]]), np.concatenate([cols, cols[:1]])    # scipy sums a repeated pair
    v = rng.standard_normal(len(twice[0]))
    fresh = _TripletsCsr()
    assert same(fresh(*twice, v, (40, 30)), sp.csr_matrix((v, twice), shape=(40, 30))) and fresh._kept is None
