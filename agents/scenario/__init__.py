"""The scenario: one enclosing experiment, described and checked (read from TOML, with its
law, by agents.loading).

- `agents.scenario.model`: the frozen `Scenario` and its parts (gains, pattern, targets, run).
- `agents.loading.scenario_file`: `load_scenario` / `parse_scenario`, the one way to build one.
- `agents.scenario.fields`, `.tables`, `.network`, `.faults`: the field readers and the
  per-table parsers, each error naming its field; `.checks`: the paper's assumptions.
- `shipped/`: the scenarios that come with enclose (paper, ring16, ring32, ring64, ring128).

The network schema (`NetworkConfig`, `LinkImpairment`) is transport's:
`transport.network_schema`.  Import from the modules; this package re-exports nothing.
"""
