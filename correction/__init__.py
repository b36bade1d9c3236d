"""The seed paper's ring-gauge pipeline, reproduced and surpassed.

Force peaks (:mod:`.signals`), the ring fits (orthogonal-distance cylinder and circles, ball compensation:
:mod:`arm_model.geometry`), the paper's four correction models and the full-wrench correction (:mod:`.models`),
correlations (:mod:`.correlation`),
GUM budgets on GTC (:mod:`.gum`), the paper's own numbers reproduced and the loop closed on its Table 2
(:mod:`.paper`), and the reports of ``aacmm ring`` / ``aacmm paper`` (:mod:`.report`). See
docs/ring-pipeline.md.
"""
from .correlation import Correlation, campaign_correlations, correlate
from .gum import Budget, BudgetResult, Term, ring_budget, student_k
from .models import (
                     MODEL_LABELS,
                     MODELS,
                     PAPER_MODELS,
                     RingCampaign,
                     RingMeasurement,
                     analyse_ring_campaign,
                     campaign_summary,
                     correct_ring,
                     paper_correction,
                     table2,
)
from .paper import close_loop, implied_forces, load_paper_table2, table1_reproduction, table3_reproduction
from .signals import ForceSummary, PointForces, find_point_forces, force_summary, forces_from_columns

__all__ = [
    "Correlation", "campaign_correlations", "correlate",
    "Budget", "BudgetResult", "Term", "ring_budget", "student_k",
    "MODEL_LABELS", "MODELS", "PAPER_MODELS", "RingCampaign", "RingMeasurement", "analyse_ring_campaign",
    "campaign_summary", "correct_ring", "paper_correction", "table2",
    "close_loop", "implied_forces", "load_paper_table2", "table1_reproduction", "table3_reproduction",
    "ForceSummary", "PointForces", "find_point_forces", "force_summary", "forces_from_columns",
]
