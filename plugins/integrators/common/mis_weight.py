"""The MIS weight of one technique's sample (Veach 1997, ch. 9), on Dr.Jit or numpy arrays.

One formula serves the lab's estimators (Dr.Jit arrays, traced into their kernels) and the
toy problems of ``mitsuba_lab.theory`` (numpy arrays); ``hit_weight`` and ``sample_weight``
are its two uses in a path: an emitter hit and an emitter sample. ``mis_weight`` is written against a
tiny namespace of array operations (``_Ops``) chosen by the type of its arguments. It imports
neither Mitsuba nor Dr.Jit itself, so it needs no variant and is never re-run on a switch.
"""
from __future__ import annotations

from mitsuba_lab.plugins.params import HEURISTICS


class _Ops:
    """The array operations ``mis_weight`` uses: select, isinf, square, power, rcp."""

    def __init__(self, module):
        self.np = None
        if module == "numpy":
            import numpy as np

            self.np = np
            self.select, self.isinf, self.square, self.power = np.where, np.isinf, np.square, np.power
            self.rcp = np.reciprocal
            self.asarray = lambda x: np.asarray(x, dtype=np.float64)
        else:
            import drjit as dr

            self.select, self.isinf, self.square, self.power = dr.select, dr.isinf, dr.square, dr.power
            self.rcp = dr.rcp
            self.asarray = lambda x: x

    def quiet(self):
        """numpy: no warnings for 0/0, x/0 and overflow, whose limits the formula selects away."""
        if self.np is None:
            import contextlib

            return contextlib.nullcontext()
        return self.np.errstate(all="ignore")


_OPS: dict[str, _Ops] = {}


def _ops_for(*values) -> _Ops:
    module = "drjit" if any(type(v).__module__.startswith("drjit") for v in values) else "numpy"
    if module not in _OPS:
        _OPS[module] = _Ops(module)
    return _OPS[module]


def mis_weight(pdf_self, pdf_other, heuristic: str = "power", beta: float = 2.0):
    """MIS weight of a sample drawn by the technique with effective density ``pdf_self``.

    ``pdf_self`` and ``pdf_other`` are n_i p_i(x) for the two techniques (Veach's
    multi-sample estimator: n_i samples of technique i, its density p_i), in the same
    measure. With r = pdf_other / pdf_self:

    * ``power`` (exponent ``beta``): w = 1 / (1 + r^beta) = (n_i p_i)^beta / sum_k (n_k p_k)^beta;
    * ``balance``: the power heuristic with beta = 1, w = n_i p_i / sum_k n_k p_k;
    * ``max``: 1 for the larger density, 0 for the smaller, 1/2 each on a tie;
    * ``average``: 1/2 wherever both techniques can sample x. This is the plain average of
      the two techniques' estimators, F = (F_A + F_B) / 2, Veach's cautionary example
      (1997, sec. 9.2): it keeps a share of the worse technique's variance wherever that
      technique is bad, which MIS weights exist to avoid. A function of the effective densities
      alone cannot tell n_A from n_B, so the plain average means 1/2 for any sample counts.

    Every heuristic gives weight 1 where only this technique can sample x (``pdf_other`` = 0)
    and 0 where it cannot (``pdf_self`` = 0, or NaN), so the two weights sum to 1 wherever either
    density is positive: the combination is unbiased. Densities may lie anywhere in [0, inf]:
    powers are taken of the ratio r, never of a density (p^beta overflows float32 once
    p > 3.4e38^(1/beta)), an overflowing r^beta gives the right limit (0), inf against a finite
    density gets 1, two infinite densities split 1/2. A NaN or negative ``pdf_other`` counts as
    0 (that technique cannot sample x), so a broken density elsewhere never makes this weight NaN.

    ``pdf_self`` and ``pdf_other`` are Dr.Jit arrays (inside the lab's kernels), or numbers /
    numpy arrays (the result is then a numpy array).
    """
    if heuristic not in HEURISTICS:
        raise ValueError(f"unknown MIS heuristic '{heuristic}'; expected one of {', '.join(HEURISTICS)}")
    if heuristic == "power" and not beta > 0:
        raise ValueError(f"the power heuristic's exponent beta must be > 0, got {beta}")
    ops = _ops_for(pdf_self, pdf_other)
    pdf_self, pdf_other = ops.asarray(pdf_self), ops.asarray(pdf_other)
    with ops.quiet():
        pdf_other = ops.select(pdf_other > 0, pdf_other, 0.0)
        if heuristic in ("balance", "power"):
            exponent = 1.0 if heuristic == "balance" else beta
            both_inf = ops.isinf(pdf_self) & ops.isinf(pdf_other)
            r = ops.select(both_inf, 1.0, pdf_other / pdf_self)
            if exponent == 1.0:
                r_beta = r
            elif exponent == 2.0:
                r_beta = ops.square(r)
            else:
                r_beta = ops.power(r, exponent)
            w = ops.rcp(1.0 + r_beta)
        elif heuristic == "max":
            w = ops.select(pdf_self > pdf_other, 1.0, ops.select(pdf_self == pdf_other, 0.5, 0.0))
        else:  # average
            w = ops.select(pdf_other > 0, 0.5, 1.0)
        return ops.select(pdf_self > 0, w, 0.0)


def hit_weight(d, heuristic: str = "power", beta: float = 2.0):
    """Weight of emission found by BSDF sampling, from the ``Densities`` ``d`` of both
    techniques (n_L p_L in ``d.emitter``): 1 after a delta lobe, which emitter sampling cannot
    produce. Where ``d.equiangular`` is given (a medium vertex), of all three techniques."""
    ops = _ops_for(d.bsdf, d.emitter, d.delta)
    if getattr(d, "equiangular", None) is None:
        return ops.select(d.delta, 1.0, mis_weight(d.bsdf, d.emitter, heuristic, beta))
    return ops.select(d.delta, 1.0, mis_weight_many(d.bsdf, (d.emitter, d.equiangular), heuristic, beta))


def sample_weight(d, heuristic: str = "power", beta: float = 2.0):
    """Weight of an emitter sample, from the ``Densities`` ``d``: 1 for a delta light, which
    BSDF sampling cannot hit. Where ``d.equiangular`` is given (a medium vertex), of all three
    techniques (equi-angular sampling reaches delta lights too)."""
    ops = _ops_for(d.bsdf, d.emitter, d.delta)
    if getattr(d, "equiangular", None) is None:
        return ops.select(d.delta, 1.0, mis_weight(d.emitter, d.bsdf, heuristic, beta))
    return mis_weight_many(d.emitter, (ops.select(d.delta, 0.0, d.bsdf), d.equiangular), heuristic, beta)


def equiangular_weight(d, heuristic: str = "power", beta: float = 2.0):
    """Weight of an equi-angular sample in a medium, from the ``Densities`` ``d`` of all three
    techniques (``d.equiangular`` its own density)."""
    ops = _ops_for(d.bsdf, d.emitter, d.delta)
    return mis_weight_many(d.equiangular, (d.emitter, ops.select(d.delta, 0.0, d.bsdf)), heuristic, beta)


def mis_weight_many(pdf_self, pdf_others, heuristic: str = "power", beta: float = 2.0):
    """MIS weight of a sample of the technique with effective density ``pdf_self`` among three or
    more techniques (``pdf_others``: the other techniques' effective densities, in the same
    measure), so that the weights of all techniques sum to 1 wherever one density is positive:

    * ``power`` / ``balance``: w = 1 / (1 + sum_j r_j^beta), r_j = pdf_j / pdf_self, each term
      taken from the two-technique weight (r_j^beta = 1 / w_j - 1), so its limits are those of
      ``mis_weight``;
    * ``max``: 1 / (number of techniques tied at the largest density) for a largest one, else 0;
    * ``average``: 1 / (number of techniques that can sample x) where this one can.
    """
    ops = _ops_for(pdf_self, *pdf_others)
    pdf_self = ops.asarray(pdf_self)
    with ops.quiet():
        if heuristic in ("balance", "power"):
            rest = 0.0
            for other in pdf_others:
                rest = rest + (ops.rcp(mis_weight(pdf_self, other, heuristic, beta)) - 1.0)
            return ops.rcp(1.0 + rest)
        count = 1.0
        beaten = pdf_self > 0
        for other in pdf_others:
            other = ops.asarray(other)
            other = ops.select(other > 0, other, 0.0)
            if heuristic == "max":
                beaten = beaten & (other <= pdf_self)
                count = count + ops.select(other == pdf_self, 1.0, 0.0)
            else:  # average
                count = count + ops.select(other > 0, 1.0, 0.0)
        return ops.select(beaten, ops.rcp(count), 0.0)
