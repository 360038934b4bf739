"""onebox's own exceptions. Each message names the offending value and says what to do.

``onebox`` prints an OneboxError as one line and exits 2, instead of a traceback.
"""

from __future__ import annotations


class OneboxError(Exception):
    """Base of every error onebox reports to its user as one line."""


class SettingError(OneboxError):
    """A setting (config file, environment variable or flag) has a value that cannot be used."""


class BusError(OneboxError):
    """Zenoh could not be opened or reached."""


class SceneError(OneboxError):
    """The scene could not be loaded or rendered."""


class RecordingError(OneboxError):
    """An MCAP file is missing, unreadable or would be overwritten."""


class NothingArrived(OneboxError):
    """Waited for a message that did not come."""
