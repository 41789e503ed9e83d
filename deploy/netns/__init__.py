"""Runs in network namespaces: `namespace` makes, watches and removes them; `run` is
`enclose run --netns` (one lossy namespace); `hosts` is `enclose run --hosts K`."""
