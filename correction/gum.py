"""GUM uncertainty budgets (JCGM 100:2008, EA-4/02) with GTC for the arithmetic.

A :class:`Budget` is a list of :class:`Term`: name, type (A or B), distribution, the standard
uncertainty of the input, the sensitivity coefficient and the degrees of freedom. Its evaluation
(:meth:`Budget.evaluate`) builds one GTC uncertain real per term (``GTC.ureal(0, u, dof)``), sums them
with their sensitivities (a linear measurement model), and takes from GTC the combined standard
uncertainty, the Welch-Satterthwaite effective degrees of freedom (``GTC.dof``) and the coverage factor
from Student's t at the chosen probability (``GTC.reporting.k_factor``); U = k u_c.

Every value carries the unit of its budget (``Budget.unit``), e.g. N or mm.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import GTC
import numpy as np

__all__ = ["Term", "Budget", "BudgetResult", "student_k", "ring_budget"]


def student_k(dof: float, probability: float = 95.0) -> float:
    """Coverage factor from Student's t for ``dof`` degrees of freedom (> 0, ``math.inf`` for the normal
    distribution) at ``probability`` [%] (in (0, 100)); a ValueError for any other (a NaN would give a NaN k)."""
    if not dof > 0:
        raise ValueError(f"degrees of freedom must be > 0 (inf for a normal distribution), got {dof!r}")
    if not 0 < probability < 100:
        raise ValueError(f"the coverage probability must be in (0, 100) %, got {probability!r}")
    return float(GTC.reporting.k_factor(dof, probability))


@dataclass(frozen=True)
class Term:
    """One term of a budget.

    Attributes:
        name: e.g. "u_rep".
        type: "A" (statistics of repeated observations) or "B" (other information).
        distribution: "normal", "rectangular", "triangular", ... (how ``u`` was obtained).
        u: standard uncertainty of the input quantity [unit of the input].
        sensitivity: sensitivity coefficient (the budget's unit per input unit).
        dof: degrees of freedom (``math.inf`` for a type B term known exactly).
        sensitivity_label: the coefficient as printed (e.g. "L dT"), when not a plain number.
        source: how ``u`` follows from its inputs (e.g. "U/k = 0.8 mg / 2").
    """
    name: str
    type: str
    distribution: str
    u: float
    sensitivity: float = 1.0
    dof: float = math.inf
    sensitivity_label: str | None = None
    source: str = ""

    def __post_init__(self):
        if self.type not in ("A", "B"):
            raise ValueError(f"term {self.name}: type must be 'A' or 'B', got {self.type!r}")
        if not (self.u >= 0 and math.isfinite(self.u)):
            raise ValueError(f"term {self.name}: standard uncertainty must be finite and >= 0, got {self.u}")
        if not self.dof > 0:
            raise ValueError(f"term {self.name}: degrees of freedom must be > 0, got {self.dof}")

    @property
    def contribution(self) -> float:
        """|sensitivity| u, in the budget's unit."""
        return abs(self.sensitivity) * self.u

    # -- constructors: each states how the standard uncertainty follows from its input -----------
    @classmethod
    def normal(cls, name, u, dof=math.inf, type="B", sensitivity=1.0, **kw) -> Term:
        """A standard uncertainty given directly (normal distribution)."""
        return cls(name, type, "normal", float(u), sensitivity, dof, **kw)

    @classmethod
    def expanded(cls, name, U, k, sensitivity=1.0, **kw) -> Term:
        """From an expanded uncertainty ``U`` with coverage factor ``k`` (a certificate): u = U / k."""
        kw.setdefault("source", f"U/k = {U:g} / {k:g}")
        return cls(name, "B", "normal", float(U) / float(k), sensitivity, math.inf, **kw)

    @classmethod
    def rectangular(cls, name, half_width, sensitivity=1.0, **kw) -> Term:
        """Rectangular distribution of half-width ``a``: u = a / sqrt(3) (``GTC.type_b.uniform``)."""
        kw.setdefault("source", f"a/sqrt(3), a = {half_width:g}")
        return cls(name, "B", "rectangular", float(GTC.type_b.uniform(half_width)), sensitivity, math.inf, **kw)

    @classmethod
    def rectangular_width(cls, name, width, sensitivity=1.0, **kw) -> Term:
        """Rectangular distribution of full width ``w`` (a resolution step): u = w / sqrt(12)."""
        kw.setdefault("source", f"w/sqrt(12), w = {width:g}")
        return cls(name, "B", "rectangular", float(GTC.type_b.uniform(width / 2.0)), sensitivity, math.inf, **kw)

    @classmethod
    def type_a(cls, name, samples, sensitivity=1.0, **kw) -> Term:
        """Type A from repeated observations: u = s / sqrt(n), n - 1 degrees of freedom
        (``GTC.type_a.estimate``)."""
        est = GTC.type_a.estimate(list(map(float, samples)))
        n = len(samples)
        kw.setdefault("source", f"s/sqrt(n), n = {n}")
        return cls(name, "A", "normal", float(est.u), sensitivity, float(est.df), **kw)


@dataclass(frozen=True)
class BudgetResult:
    """An evaluated budget [the budget's unit]: ``u_c`` combined standard uncertainty, ``dof``
    Welch-Satterthwaite effective degrees of freedom, ``k`` coverage factor at ``probability`` [%],
    ``U`` = k u_c, and ``influences`` (name, contribution) in decreasing order, as GTC reports them."""
    name: str
    unit: str
    terms: tuple
    u_c: float
    dof: float
    k: float
    U: float
    probability: float
    influences: tuple

    def as_dict(self) -> dict:
        def num(x):
            return None if x is None else ("inf" if x == math.inf else float(x))
        return {"name": self.name, "unit": self.unit, "probability_pct": self.probability,
                "combined_standard_uncertainty": self.u_c, "effective_dof": num(self.dof),
                "coverage_factor": self.k, "expanded_uncertainty": self.U,
                "terms": [{"name": t.name, "type": t.type, "distribution": t.distribution, "u": t.u,
                           "sensitivity": t.sensitivity, "sensitivity_label": t.sensitivity_label,
                           "dof": num(t.dof), "contribution": t.contribution, "source": t.source}
                          for t in self.terms]}


@dataclass(frozen=True)
class Budget:
    """A list of terms, combined linearly: y = sum(sensitivity_i x_i)."""
    name: str
    terms: tuple
    unit: str = ""
    probability: float = 95.0
    notes: tuple = field(default=())

    def evaluate(self, probability: float | None = None, dof: float | None = None) -> BudgetResult:
        """Combine the terms with GTC.

        Args:
            probability: coverage probability [%] (default the budget's).
            dof: override the effective degrees of freedom used for k (to reproduce a printed budget);
                None uses Welch-Satterthwaite.
        """
        p = self.probability if probability is None else probability
        if not self.terms:
            raise ValueError(f"budget {self.name}: no terms")
        y = 0.0
        for t in self.terms:
            y = y + t.sensitivity * GTC.ureal(0.0, t.u, t.dof, label=t.name)
        u_c = float(GTC.uncertainty(y))
        nu = float(GTC.dof(y)) if dof is None else float(dof)
        k = student_k(nu, p)
        influences = tuple((c.label, float(c.u)) for c in GTC.reporting.budget(y))
        return BudgetResult(self.name, self.unit, self.terms, u_c, nu, k, k * u_c, p, influences)


def ring_budget(name: str, values, length: float, u_ring: float | None, u_cor: float | None = None, *,
                delta_t: float = 0.5, u_alpha: float = 1e-6, resolution: float = 1e-7,
                probability: float = 95.0, u_ring_source: str = "", ring_half_width: float | None = None) -> Budget:
    """The seed paper's ring-gauge test budget (its Eq. 10-16) for one quantity of a campaign, in mm.

    Args:
        name: e.g. "diameter, full wrench".
        values: (M,) the quantity per measurement (diameters or form errors) [m]; u_r = s / sqrt(M), type A,
            M - 1 degrees of freedom.
        length: L of the thermal term u_t = L dT u(alpha) [m] (the diameter, or the form error).
        u_ring: standard uncertainty of the reference [m] (certificate U / k), or None to leave it out.
        u_cor: standard uncertainty of the correction [m] (2 c u_force for the diameter), None without model.
        delta_t: temperature variation during the test [C]; u_alpha: uncertainty of the expansion
            coefficient [1/C] (the paper: 0.5 C, 1e-6 /C).
        resolution: resolution of the reported values [m] (the paper's software: 0.0001 mm), w/sqrt(12).
        ring_half_width: instead of ``u_ring``, a reference known only by bounds +-a [m] (the ring's certified
            form error): a rectangular term, u = a / sqrt(3), labelled so in the budget.
    """
    mm = 1e3
    terms = []
    if ring_half_width is not None:
        terms.append(Term.rectangular("u_ring", ring_half_width * mm, source=u_ring_source or "a/sqrt(3)"))
    elif u_ring is not None:
        terms.append(Term.normal("u_ring", u_ring * mm, source=u_ring_source or "artefact certificate"))
    terms.append(Term.type_a("u_r", np.asarray(values, float) * mm))
    terms.append(Term.normal("u_t", length * delta_t * u_alpha * mm, sensitivity_label="L dT",
                             source=f"L dT u(alpha): L = {length * mm:.4g} mm, dT = {delta_t:g} C, "
                                    f"u(alpha) = {u_alpha:g} /C"))
    terms.append(Term.rectangular_width("u_res", resolution * mm))
    if u_cor is not None:
        terms.append(Term.normal("u_cor", u_cor * mm, source="2 c u_force"))
    return Budget(name, tuple(terms), "mm", probability)
