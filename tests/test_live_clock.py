"""A live session whose time stamps jump (docs/live.md, "Time stamps off the clock"): one sample far ahead of or
behind the stream's clock is one bad time stamp (said with its line, skipped, its slot dropped) and the session
goes on; a jump the next samples keep (a device clock reset) is one clock jump, said once, and the session
follows the new clock. The bundled stream (1 kHz, 19 contacts) is the reference: every point of it is found
again, at the same encoder readings, with the same peak force."""
from __future__ import annotations

import csv

import numpy as np
import pytest

from arm_model.cli import main
from arm_model.io import read_points
from arm_model.live import Session, read_status
from arm_model.live.session import JUMP_CONFIRM
from conftest import ROOT

LINES = (ROOT / "examples" / "live" / "samples.csv").read_text().splitlines(keepends=True)
#: the stream's line (1-based, the header is line 1) of a sample out of contact (t = 0.3 s) and of one in the first
#: contact after its peak (t = 0.65 s; it lasts from 0.545 to 0.725 s, its peak at 0.609 s)
FREE, IN_CONTACT = 302, 652


def rows(path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def with_times(change) -> str:
    """The bundled stream with the time of each sample line ``no`` (1-based) replaced by ``change(no, t)``."""
    out = [LINES[0]]
    for no, line in enumerate(LINES[1:], start=2):
        t, rest = line.split(",", 1)
        out.append(f"{change(no, float(t))!r},{rest}" if change(no, float(t)) is not None else line)
    return "".join(out)


def live(tmp_path, text: str, name: str):
    src = tmp_path / f"{name}.csv"
    src.write_text(text)
    out = tmp_path / name
    assert main(["live", str(src), "--arm", "aacmm7", "-o", str(out), "--speed", "0", "-q"]) == 0
    status = read_status(out)
    assert status["status"] == "complete"
    assert (out / "samples.csv").read_text() == text           # the stream as received, off-clock lines too
    return out, status["counts"], rows(out / "events.csv"), read_points(out / "points.csv", 7)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out, counts, events, points = live(tmp_path_factory.mktemp("ref"), "".join(LINES), "ref")
    assert counts["points"] == 19 and counts["time_jumps"] == counts["clock_jumps"] == counts["late"] == 0
    return points, rows(out / "contacts.csv")


def same_points(got, ref, shift=0.0, after=np.inf):
    assert np.array_equal(got.q, ref.q) and np.array_equal(got.force, ref.force)
    assert np.allclose(got.time, np.where(ref.time > after, ref.time + shift, ref.time), rtol=0, atol=1e-9)


@pytest.mark.parametrize("bad", [1e6, -50.0, 0.3 - 2.0])
def test_one_time_stamp_far_off_is_one_bad_sample(tmp_path, reference, bad):
    """A corrupted time stamp far ahead (t = 1e6 s at 1 kHz) or behind: that sample is skipped, said with its line;
    every point of the stream is found again and nothing else is late."""
    out, counts, events, points = live(tmp_path, with_times(lambda no, t: bad if no == FREE else None), "spike")
    same_points(points, reference[0])
    assert counts["time_jumps"] == 1 and counts["clock_jumps"] == 0 and counts["late"] == 0
    assert counts["dropped"] == 1 and counts["samples"] == len(LINES) - 2        # its slot is missing
    (ev,) = [e for e in events if e["kind"] == "time_jump"]
    assert ev["message"].startswith(f"line {FREE}: a sample at t = {bad!r} s") and "skipped" in ev["message"]
    assert float(ev["time_s"]) == bad


@pytest.mark.parametrize("jump", [1e6, -0.3, -3600.0])
def test_a_clock_that_jumps_and_stays_is_followed(tmp_path, reference, jump):
    """From line FREE on, every time stamp is moved by ``jump`` (forward; back to about 0, a device clock reset;
    an hour back): one clock jump, said once; the session follows the new clock and finds every point, those
    after the jump at their new times."""
    text = with_times(lambda no, t: t + jump if no >= FREE else None)
    out, counts, events, points = live(tmp_path, text, "jump")
    same_points(points, reference[0], jump, after=0.3 - 1e-9)
    assert counts["clock_jumps"] == 1 and counts["time_jumps"] == 0 and counts["late"] == 0
    assert counts["dropped"] == 0 and counts["samples"] == len(LINES) - 1
    (ev,) = [e for e in events if e["kind"] == "clock_jump"]
    # the jump from the last sample on the old clock (0.299 s) to the first on the new one
    assert ev["message"].startswith(f"line {FREE}: the time stamps jumped by {(0.3 + jump) - 0.299:+.6g} s (from "
                                    f"0.299 to {0.3 + jump!r} s)")
    assert float(ev["time_s"]) == pytest.approx(0.3 + jump, abs=1e-9)


def test_a_clock_jump_during_a_contact_ends_it_there(tmp_path, reference):
    """The clock jumps back by 100 s inside the first contact: the contact ends at its last sample before the jump
    (its peak, at 0.609 s, is before it: the same point), said; the rest of the press, on the new clock, is one more
    contact. Every later point is found again."""
    text = with_times(lambda no, t: t - 100.0 if no >= IN_CONTACT else None)
    out, counts, events, points = live(tmp_path, text, "in-contact")
    ref = reference[0]
    assert counts["clock_jumps"] == 1 and counts["time_jumps"] == 0 and counts["late"] == 0
    msgs = [e["message"] for e in events if e["kind"] == "clock_jump"]
    assert len(msgs) == 2 and "a contact was open at the clock jump" in msgs[1] and "contact 1" in msgs[1]
    contacts = rows(out / "contacts.csv")
    assert float(contacts[0]["end_s"]) == pytest.approx(0.649) and float(contacts[0]["peak_s"]) == 0.609
    assert np.array_equal(points.q[0], ref.q[0])
    # the press goes on after the jump: one more contact, on the new clock; the others are the reference's
    assert len(points) == len(ref) + 1 and float(contacts[1]["start_s"]) == pytest.approx(0.65 - 100.0)
    assert np.array_equal(points.q[2:], ref.q[1:])


def test_samples_held_off_the_clock_at_the_end_are_bad_time_stamps():
    """The stream ends while fewer than JUMP_CONFIRM samples stand on a new clock: they are bad time stamps (skipped),
    never silent."""
    s = Session("aacmm7", rate=1000.0)
    q = np.radians([10.0, 35.0, -5.0, 70.0, 3.0, 40.0, 8.0])
    for k in range(200):
        s.push(k * 1e-3, q, (0.0, 0.0, 0.0))
    for k in range(JUMP_CONFIRM - 1):
        assert s.push(500.0 + k * 1e-3, q, (0.0, 0.0, 0.0)) == ()      # held: not yet known
    out = s.close()
    assert [e.kind for e in out] == ["time_jump"] * (JUMP_CONFIRM - 1)
    assert s.counts["time_jumps"] == JUMP_CONFIRM - 1 and s.counts["samples"] == 200 and s.counts["clock_jumps"] == 0
