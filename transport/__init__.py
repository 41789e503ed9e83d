"""Message layer of the swarm: bus interface, Zenoh and in-memory buses, codec, keys.

Import the pieces from their modules; the Zenoh bus lives in `transport.zenoh_bus`
so that pure tests need not import zenoh.
"""
