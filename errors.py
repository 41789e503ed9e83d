"""Every named error of enclose, in one place.

Each layer raises one of these so that entry points can turn them into a
clear message and an exit code instead of a traceback.
"""

from __future__ import annotations


class EncloseError(Exception):
    """Base of all errors raised on purpose by enclose."""


class ConfigError(EncloseError):
    """A configuration value is missing, of the wrong type or out of range.

    `field` is the dotted path of the offending value (e.g. `pattern.rho_d_m`).
    """

    def __init__(self, field: str, reason: str) -> None:
        super().__init__(f"{field}: {reason}")
        self.field = field
        self.reason = reason


class ScenarioError(ConfigError):
    """A scenario file is unreadable or invalid."""


class InadmissibleError(ConfigError):
    """The pattern, graph or observation map violates the paper's assumptions."""


class CodecError(EncloseError):
    """A bus payload could not be decoded (bad msgpack, version, schema or non-finite number).

    `reason` is a short tag (msgpack, version, schema, type, non_finite, ...) used to count drops.
    """

    def __init__(self, message: str, reason: str = "invalid") -> None:
        super().__init__(message)
        self.reason = reason


class TransportError(EncloseError):
    """The message bus could not be opened or used."""


class MavlinkError(EncloseError):
    """A MAVLink exchange failed (no heartbeat, command denied, timeout)."""


class LinkLostError(MavlinkError):
    """No telemetry from the vehicle within the link-loss timeout."""


class CommandRejectedError(MavlinkError):
    """The vehicle answered a command with something other than ACCEPTED."""

    def __init__(self, command: int, result: int, detail: str = "") -> None:
        super().__init__(f"command {command} rejected with result {result} {detail}".strip())
        self.command = command
        self.result = result


class SimulatorError(EncloseError):
    """The vehicle simulator could not start or keep real time."""


class DeployError(EncloseError):
    """A launched process failed to start, link or exit cleanly."""


class JournalError(EncloseError):
    """A follower's input journal cannot be read: another version, or a damaged record.

    `path` and `offset` (bytes from the file's start) name where.
    """

    def __init__(self, path: str, offset: int, reason: str) -> None:
        super().__init__(f"{path} at byte {offset}: {reason}")
        self.path = path
        self.offset = offset
        self.reason = reason
