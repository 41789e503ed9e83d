"""Message layer of the swarm.

- `transport.bus`: the `Bus` protocol (publish / declare_publisher, subscribe -> drain(),
  declare_token / watch_alive, close, context manager), `Received`, `Congestion`,
  `wait_until_alive`.
- `transport.zenoh_bus.ZenohBus(ZenohConfig)`: the real bus; `transport.zenoh_config`
  builds its safe config (peer, 127.0.0.1, no multicast, HLC timestamps).
- `transport.memory_bus.MemoryBus(MemoryHub())`: the same semantics in memory, for unit tests.
- `transport.messages`: frozen message dataclasses, `Header`, `Stamper`.
- `transport.codec`: versioned msgpack `encode` / `decode` (raise `CodecError`);
  `transport.decoder.Decoder`: drop-and-count decoding for process loops.
- `transport.key_exprs.SwarmKeys`: every key expression, under `enclose/<swarm>/`.

Import from the modules; this package imports nothing so that pure tests need not load zenoh.
"""
