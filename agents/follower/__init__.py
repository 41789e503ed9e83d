"""A follower process, one file per step of its tick, read top to bottom in node.py:
membership.py (its place in the ring the members form), inputs.py (what it received, as
its law reads it), runner.py (its law, guarded), node.py (the loop: receive, run the law,
command the vehicle, publish), main.py (the process: `python -m agents.follower.main`).
"""
