"""Live measurement sessions: samples streamed in, corrected points with their uncertainty out, as the
operator probes (docs/live.md).

:class:`Session` takes samples one at a time (``push(t, q, wrench)``), finds contacts, gives one point a
contact at its force peak (``aacmm tip``'s code: every effect of a model file applied), its uncertainty,
over-force and joint-limit events as they happen, and refits the features of a plan after each point;
with a folder, it records everything as it goes (:mod:`arm_model.live.record`).
"""
from .contacts import Contact, ContactDetector, ContactOptions
from .features import FeatureFit, FeatureTracker
from .plan import PlanFeature, SessionPlan, parse_plan, read_plan, single_feature_plan
from .record import FILES, SessionRecord, read_status
from .samples import Sample, SampleLayout, sample_header
from .session import Event, LivePoint, Session

__all__ = ["Session", "LivePoint", "Event", "Contact", "ContactOptions", "ContactDetector", "FeatureFit",
           "FeatureTracker", "SessionPlan", "PlanFeature", "read_plan", "parse_plan", "single_feature_plan",
           "Sample", "SampleLayout", "sample_header", "SessionRecord", "read_status", "FILES"]
