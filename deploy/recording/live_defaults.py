"""What the launcher knows of the recorder without importing it: where the live view listens
by default (apart from live_server: no foxglove-sdk, and mcap with it:
tests/unit/test_lean_start) and the name of the progress file it reads the live URL from
(apart from deploy.recording.progress: no numpy, ~0.2 s of the launcher's start)."""

DEFAULT_PORT = 8765
DEFAULT_HOST = "127.0.0.1"  # loopback only: the view has no authentication

PROGRESS_FILE = "progress.json"  # the recorder writes it (deploy.recording.loop)
