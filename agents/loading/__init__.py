"""A scenario as a run uses it: read from TOML, checked, and its law built and checked by
that law (the one way to build one; above agents.scenario, which describes it, and
agents.law, which reads it)."""
