"""A swarm over several hosts: the deployment file, per-host credentials, routers, each host's
launcher."""
