"""The project's exception hierarchy.

Every error raised on purpose by this project derives from :class:`RigError`, so a caller (the CLI
in particular) can report it in words and exit cleanly. Each message says what went wrong, where
(file, device, axis, parameter) and, when it is not obvious, what to do.
"""

from __future__ import annotations


class RigError(Exception):
    """Root of every error this project raises on purpose."""


class InputError(RigError, ValueError):
    """A value, argument or file given by the user is not acceptable."""


class NotApplicable(InputError):
    """A method cannot be applied to this field: too few lights for its terms, or a part it needs.

    A choice among methods leaves such a candidate out and says why; any other error stops it.
    """


class PanoramaError(InputError):
    """A panorama file cannot be used as an environment (unreadable, wrong shape, bad values)."""


class DeviceError(RigError):
    """A device did not answer, answered wrongly, or reported a fault."""


class ProtocolError(DeviceError):
    """Bytes on the wire did not follow the device's protocol."""


class DeviceFault(DeviceError):
    """A device reported a fault of its own that a person must clear.

    A GRBL alarm, a servo's hardware error: retrying the command cannot help, unlike a lost or
    refused reply. The executor catches this marker, never a driver's own error types.
    """


class SafetyError(RigError):
    """A requested motion or action would violate a safety limit; nothing was sent."""


class ConfigError(InputError):
    """A rig configuration file is invalid."""


class DatasetError(RigError):
    """A capture dataset or reflectance-field store is missing, corrupt or inconsistent."""


class ClusterError(RigError):
    """The Dask cluster a stage was sent to cannot be reached."""
