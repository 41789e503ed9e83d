"""The estimator's velocity stage (order 2): a second consensus, on the targets' mean velocity.

    rv_i = Psi_i + dp~_i/dt,   dPsi_i/dt = k_e * sum_j a_ij sig(rv_j - rv_i)^(1/alpha1),
    dPhi_i/dt = (the consensus on r, agents.law.consensus) + Psi_i

Not the paper's law: the paper's estimator (a first-order dynamic average consensus)
needs a standing difference between neighbours' estimates to carry the targets' velocity
difference round a ring.  Fed Psi_i, Phi_i carries it in its rate instead, and the gap
left is set by how fast that difference changes.  Psi_i's flows are the consensus's own
law (`agents.law.consensus.link_flow` on rv); with the robust estimator Psi_i is the
balance of its own link sums, like Phi_i.
"""

from __future__ import annotations


def lap_velocity(psi_m_s: complex, p_tilde_rate_m_s: complex) -> complex:
    """rv_i = Psi_i + dp~_i/dt: follower i's estimate of the LAP's velocity."""
    return psi_m_s + p_tilde_rate_m_s


def fed_flow(flow_m_s: complex, psi_share_m_s: complex) -> complex:
    """A flow of Phi_i with the velocity stage fed in (dPhi_i/dt = consensus + Psi_i).

    Per follower `psi_share_m_s` is Psi_i; per link (robust) it is the link's own velocity
    sum, so that the link's two ends still balance exactly and mean(r) stays the LAP."""
    return flow_m_s + psi_share_m_s
