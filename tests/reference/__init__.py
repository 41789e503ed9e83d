"""Reference oracles: the paper's equations written plainly in numpy, for the tests only.

agents.law writes each equation once, as scalar Python on complex plane vectors, for the
follower processes and (compiled) the lock-step engine.  These are the same equations
written independently, as the paper states them, on (k, 2) arrays: real vectors phi_i and
phi_perp_i instead of complex products, a whole swarm's rates from its graph's edge
operators, and the lock-step loop as plain numpy (`lockstep`).
"""
