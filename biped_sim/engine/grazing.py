"""A dip of the swing foot below the ground inside one step, found with a guarantee.

A step whose two ends have the swing foot above the ground can still hide a dip below it (a graze
of tens of micrometres at a few cm/s). The integrator's dense output over the step is a polynomial
in s = (t - t_old) / h of degree at most 7 (DOP853's; DOPRI5's is 4, the Hermite and scipy's
interpolants lower): its power-basis coefficients come from the interpolant itself
(``poly_coefficients``), or exactly (to roundoff) from its values at 8 Chebyshev points.
The foot's height along it is not a polynomial (sines and cosines of the link angles), but its second
derivative in s is bounded on any [a, b] from the polynomials' derivative bounds:

    |h''| <= |y''| + |tan(slope)| |x''| + sum_k l_k (1 + |tan(slope)|) (|a_k''| + a_k'^2)

(the floating base's point (x, y), and the links of the foot's chain from it: each link k's absolute angle a_k
and its length l_k from its joint to the next joint or the foot; for the three-link biped the chain is the leg;
on the fixed base the hip's terms become those of the stance leg's angle). Then h >= min(h(a), h(b)) -
M2 (b - a)^2 / 8 on [a, b]: an interval where that is positive holds no dip; the others are halved, down to the
width at which M2 (b - a)^2 / 8 <= graze_tol. So a dip of the dense output's foot height deeper than
``graze_tol`` inside a step is always found, and its crossing is returned as a bracket for the root finder
(the rule ``loop_rules.ev_dip_search`` derives the bound).
"""
from __future__ import annotations

import numpy as np

from biped_sim.engine import loop_rules as rules
from biped_sim.engine.loop_state import (
    CHAIN,
    CHAIN_LINKS,
    CHAIN_MAX,
    CHAIN_WIDTH,
    COEF,
    COEF_WIDTH,
    FIXED_BASE,
    GRAZE_TOL,
    RESULT,
    TAN_S,
    TERMS_MAX,
    new_state,
)

DEGREE = 7
NODES = 0.5 - 0.5 * np.cos((2 * np.arange(DEGREE + 1) + 1) * np.pi / (2 * (DEGREE + 1)))   # in (0, 1)
_VANDERMONDE_INV = np.linalg.inv(np.vander(NODES, DEGREE + 1, increasing=True))


def _guard(S, height_at, t):
    """A Python function of t as the rules call a guard: g(S, ctx, t), ctx the function."""
    return height_at(t)


def contact_chains(model):
    """Per contact point (two), its chain from the floating base's point: ((l_k, terms), ...) a link each, l_k the
    distance (m) its absolute angle turns, terms the entries of y whose sum is that angle as +-(entry + 1). The
    three-link biped's: its leg (the leg's angle plus the torso's); a described robot's: ``contact_chains`` of
    its :class:`~biped_sim.engine.generated_model.GeneratedModel`."""
    chains = getattr(model, "contact_chains", None)
    if chains is not None:
        return chains
    l_leg = model.parameters.l_leg
    return (((l_leg, (3, 5)),), ((l_leg, (4, 5)),))


def chain_fields(model) -> dict:
    """The state's fields of the contact points' chains (loop_state: chain_links, chain), for ``write``."""
    chains = contact_chains(model)
    flat = [0.0] * (2 * CHAIN_MAX * CHAIN_WIDTH)
    for c, chain in enumerate(chains):
        if len(chain) > CHAIN_MAX or any(len(terms) > TERMS_MAX for _, terms in chain):
            raise ValueError(f"{getattr(model, 'name', 'the model')}: contact point {c + 1}'s chain has "
                             f"{len(chain)} links (at most {CHAIN_MAX}, each angle of at most {TERMS_MAX} joints): "
                             "the engine's grazing bound has no room for it")
        for k, (length, terms) in enumerate(chain):
            at = CHAIN_WIDTH * (CHAIN_MAX * c + k)
            flat[at:at + 2 + len(terms)] = [float(length), float(len(terms))] + [float(e) for e in terms]
    return dict(chain_links=[float(len(chain)) for chain in chains], chain=flat)


def _signed_sum(C, columns, terms):
    """The signed sum of the columns of C (the entries of y ``columns`` names) that ``terms`` (+-(entry + 1)) name."""
    out = None
    for e in terms:
        v = C[:, columns.index(abs(e) - 1)] * (1.0 if e > 0 else -1.0)
        out = v if out is None else out + v
    return out


def dip_bracket(st, to_phys, height_at, leg, stance_leg, fixed_base, chains, tan_slope, h0, h1, graze_tol,
                fixed_chains=False):
    """(t_a, t_b) with the foot's height > 0 at t_a and <= 0 at t_b inside the last step, or None if
    no dip deeper than ``graze_tol`` exists there. ``height_at(t) -> float`` on the dense output;
    h0, h1: the heights at the step's ends (both > 0); ``chains``: the model's ``chain_fields``. The search and
    its bound are the rule ``loop_rules.ev_dip_search``; on the floating base, the coefficients of a dop853 or
    dopri5 step are ``loop_rules.ev_dip_coefficients``' (the compiled loop's rules, the same bits).
    ``fixed_chains``: a described robot's fixed base, y = (q[2:], dq[2:], work): the foot hangs from the pin by
    the stance foot's chain and its own, and the bound sums over both (no base terms)."""
    dense_state = None if fixed_base else getattr(st, "dense_state", None)
    interpolant = None if dense_state is not None else st.dense_output()
    S = dense_state() if dense_state is not None else getattr(interpolant, "state", None)
    if S is not None and not fixed_base:     # dop853's or dopri5's rows, in the stepper's or interpolant's state
        if S[CHAIN_LINKS + leg - 1] == 0.0:  # (a state of the stepper's own, or the interpolant's: floats already)
            S[CHAIN_LINKS:CHAIN_LINKS + 2] = chains["chain_links"]
            S[CHAIN:CHAIN + len(chains["chain"])] = chains["chain"]
        rules.ev_dip_coefficients(S, leg)
    else:
        t_old, h_step = st.t_old, st.t - st.t_old
        chain = chains["chain"][CHAIN_WIDTH * CHAIN_MAX * (leg - 1):CHAIN_WIDTH * CHAIN_MAX * leg]
        links = int(chains["chain_links"][leg - 1])
        rows = [chain[CHAIN_WIDTH * k:CHAIN_WIDTH * k + CHAIN_WIDTH] for k in range(links)]
        if fixed_base and fixed_chains:     # the stance foot's chain after the foot's own
            other = chains["chain"][CHAIN_WIDTH * CHAIN_MAX * (stance_leg - 1):CHAIN_WIDTH * CHAIN_MAX * stance_leg]
            rows += [other[CHAIN_WIDTH * k:CHAIN_WIDTH * k + CHAIN_WIDTH]
                     for k in range(int(chains["chain_links"][stance_leg - 1]))]
            if len(rows) > CHAIN_MAX:
                raise ValueError(f"the fixed base's grazing bound has room for {CHAIN_MAX} links, the feet's chains "
                                 f"have {len(rows)}: run base='floating'")
        terms = [[int(e) for e in row[2:2 + int(row[1])]] for row in rows]
        # the entries of the integrated state y the foot's height depends on
        if fixed_base and fixed_chains:     # y = (q[2:], dq[2:], work): q's entry i is y's i - 2
            terms = [[e - 2 if e > 0 else e + 2 for e in t] for t in terms]
            columns = sorted({abs(e) - 1 for t in terms for e in t})
        elif fixed_base:   # y = (q1, q2, q3, dq...): the hip hangs from the pin by the stance leg
            columns = [leg - 1, 2, stance_leg - 1]
        else:            # y = (x, y, the joints..., dq...)
            columns = [0, 1] + sorted({abs(e) - 1 for t in terms for e in t})
        if hasattr(interpolant, "poly_coefficients"):
            C = interpolant.poly_coefficients(columns)
        else:
            C = _VANDERMONDE_INV @ np.array([np.asarray(interpolant(t_old + s * h_step))[columns] for s in NODES])
        # |coefficients| (loop_state's coef): the base's x and y, then each chain link's angle; on the fixed base
        # the stance leg's angle, 0, the swing leg's
        if fixed_base and not fixed_chains:
            A = np.abs(np.column_stack([C[:, 2] + C[:, 1], np.zeros(8), C[:, 0] + C[:, 1]]))
            lengths = [rows[0][0]]
        elif fixed_base:    # no base terms: the bound's floating form with x and y zero
            A = np.abs(np.column_stack([np.zeros(8), np.zeros(8)] + [_signed_sum(C, columns, t) for t in terms]))
            lengths = [row[0] for row in rows]
        else:
            A = np.abs(np.column_stack([C[:, 0], C[:, 1]] + [_signed_sum(C, columns, t) for t in terms]))
            lengths = [row[0] for row in rows]
        S = new_state(t_old=st.t_old, t=st.t, coef_links=len(lengths), coef_length=lengths)
        for p in range(8):
            S[COEF + COEF_WIDTH * p:COEF + COEF_WIDTH * p + A.shape[1]] = A[p].tolist()
    S[FIXED_BASE], S[TAN_S], S[GRAZE_TOL] = float(fixed_base and not fixed_chains), tan_slope, graze_tol
    if rules.ev_dip_search(S, _guard, height_at, h0, h1):
        return S[RESULT], S[RESULT + 1]
    return None
