"""A follower process: its loop (node.py), its inputs (inputs.py), its ring (membership.py).

`python -m agents.follower.main --help` starts one.
"""
