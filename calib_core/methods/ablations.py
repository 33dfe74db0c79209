"""Ablations of ``peng2022`` as registered method variants (to explain the gap between our reproduction and the paper).

Each variant is ``peng2022`` with one option fixed (a ``functools.partial``, not a copy of the method):

===================  ===============================  ===============================================
name                 option                           can it change the chosen candidate?
===================  ===============================  ===============================================
peng2022/equal       ``weighting="equal"``            yes: drops the 1/beta_i exponents
peng2022/plane       ``error="point_plane"``          yes: another error (all points, not endpoints)
peng2022/delta10     ``delta_m=0.010``                yes: changes pi's shape and, through O_i U_i,
peng2022/delta100    ``delta_m=0.100``                the weights
peng2022/delta30m    ``delta_m=30.0`` (30 m, "mm" vs "m")
peng2022/nonorm      ``normalise_candidates=False``   no: ``log pi_{j,i}`` shifts by a per-board
                                                      constant c_i; O_i, U_i are computed from the
                                                      normalised pi either way (selection.py), so
                                                      beta is unchanged and sum_i w_i c_i is the same
                                                      for every candidate
peng2022/betamax     ``beta_norm="max"``              only through the zero guard: dividing beta by
peng2022/betanone    ``beta_norm="none"``             s > 0 multiplies every exponent by s, which keeps
                                                      the argmax -- unless some beta_i falls below
                                                      ``beta_eps`` (relative to s), where the guarded
                                                      weight 1/eps no longer scales with s
===================  ===============================  ===============================================
"""

from __future__ import annotations

from functools import partial, update_wrapper

from ..registry import Method, accepted_options

ABLATIONS: dict[str, dict] = {
    "peng2022/equal": {"weighting": "equal"},
    "peng2022/plane": {"error": "point_plane"},
    "peng2022/delta10": {"delta_m": 0.010},
    "peng2022/delta100": {"delta_m": 0.100},
    "peng2022/delta30m": {"delta_m": 30.0},
    "peng2022/nonorm": {"normalise_candidates": False},
    "peng2022/betamax": {"beta_norm": "max"},
    "peng2022/betanone": {"beta_norm": "none"},
}
"""Variant name -> the ``peng2022`` options it fixes."""

INVARIANT = ("peng2022/nonorm",)
"""Variants that provably choose the same candidate as ``peng2022`` (up to rounding)."""

SCALE_ONLY = ("peng2022/betamax", "peng2022/betanone")
"""Variants that rescale every exponent by one positive number: same choice unless the zero guard bites."""


def ablations(base: Method) -> list[Method]:
    """Every ``ABLATIONS`` variant of the method ``base`` (``peng2022``)."""
    out = []
    for name, fixed in ABLATIONS.items():
        func = update_wrapper(partial(base.func, **fixed), base.func)
        opts = ", ".join(f"{k}={v!r}" for k, v in fixed.items())
        out.append(Method(name, func, base.min_boards, base.citation, f"ablation: {base.name} with {opts}",
                          cost=base.cost, paper=base.paper, options=accepted_options(base)))
    return out
