"""The loop's verdict says what was added, what was built from the residual and not added (with why), and
what remains (and whether any effect exists for it), in that order; checked against hand-written sentences
on stand-in stages (the sentence only reads names, held-out figures and s0)."""
from __future__ import annotations

from types import SimpleNamespace

from arm_model import load_description
from arm_model.effects import ApproachOffset, EncoderEccentricity
from arm_model.model import ArmModel
from calibration.candidates import Candidate
from calibration.loop import LoopSettings, verdict_text
from calibration.synthesis import RESIDUAL
from conftest import NOMINAL


def _stage(added, rms, mx, s0=1.0):
    return SimpleNamespace(added=added, heldout={"rms_um": rms, "max_um": mx}, result=SimpleNamespace(s0=s0), cv=[])


def _family(name, best):
    return (SimpleNamespace(name=name), SimpleNamespace(best=best), 1e-6)


def test_verdict_names_what_was_added_built_and_what_remains():
    desc = load_description(NOMINAL)
    ecc = Candidate("eccentricity j2", EncoderEccentricity(joints=(1,)), "eccentricity", "j2")
    lob = Candidate("approach offset", ApproachOffset(), "approach_offset", origin=RESIDUAL)
    stages = [_stage(None, 6.0, 20.0), _stage(ecc, 3.0, 9.0), _stage(lob, 2.0, 6.0)]
    model = ArmModel(desc, (ecc.effect, lob.effect))
    built = [{"name": "approach offset", "added": True, "why_not_added": None},
             {"name": "harmonics j6 of q2 (h 1)", "added": False,
              "why_not_added": "not significant on held-out data (Wilcoxon p = 0.2 >= 0.005)"}]
    remains = [_family("q2 harmonics on j6", "cos/sin(1 q2)"), _family("time", "time: base x")]
    v = verdict_text(stages, remains, "", LoopSettings(), built, model)
    assert v == ("effects added: eccentricity j2, approach offset (found from the residual); held-out test RMS "
                 "6.00 -> 2.00 um, max 20.00 -> 6.00 um. Built from the residual, not supported, not added: "
                 "harmonics j6 of q2 (h 1) (not significant on held-out data (Wilcoxon p = 0.2 >= 0.005)). "
                 "Structured residual remains, not explained by the effect library nor by the effects built from "
                 "it (no further effect is built for time): it correlates with q2 harmonics on j6 (cos/sin(1 q2)); "
                 "time (time: base x). No fix is claimed for it.")


def test_verdict_when_nothing_remains_and_when_the_library_alone_ran():
    stages = [_stage(None, 2.0, 5.0)]
    assert verdict_text(stages, [], "", LoopSettings(), [], None) == (
        "no effect added. No structured residual remains (no regressor family is significant after Bonferroni's "
        "correction).")
    v = verdict_text(stages, [_family("q2 harmonics", "cos/sin(3 q2)")], "", LoopSettings(synthesise=False), [], None)
    assert v == ("no effect added. Structured residual remains, not explained by the effect library (effects are "
                 "not built from the residual: library only): it correlates with q2 harmonics (cos/sin(3 q2)). "
                 "No fix is claimed for it.")
    v = verdict_text([_stage(None, 2.0, 5.0, s0=4.0)], [], "", LoopSettings(), [], None)
    assert v.startswith("no effect added. The final residual is s0 = 4 times the stated uncertainties")
