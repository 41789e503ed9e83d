"""Where the live view listens by default: apart from live_server so that the launcher can
offer the flags without importing foxglove-sdk (and mcap with it: tests/unit/test_lean_start)."""

DEFAULT_PORT = 8765
DEFAULT_HOST = "127.0.0.1"  # loopback only: the view has no authentication
