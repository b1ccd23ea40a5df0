"""One exception family for everything a user can get wrong.

Every error raised for bad input (a malformed map, a goal inside a wall, NaN coordinates, a wrong
checkpoint) derives from :class:`EcahdError`, so a ROS node can catch exactly these, log the
message and keep running. They also derive from ``ValueError`` so generic callers still see a
value problem.
"""


class EcahdError(ValueError):
    """Base class of all ecahd_ros input errors."""


class MapError(EcahdError):
    """A map that cannot be used: malformed YAML or image, wrong shape, no free cell."""


class FootprintError(EcahdError):
    """A robot footprint that cannot be used: unknown preset, malformed polygon string."""


class PlanningError(EcahdError):
    """A planning request that cannot be served: start/goal in an obstacle or off the map, NaN."""


class TrajectoryError(EcahdError):
    """A trajectory tensor with the wrong shape, no points, or non-finite values."""


class CheckpointError(EcahdError):
    """A model checkpoint that is missing, corrupt, or made for another map / robot / horizon."""


class DatasetError(EcahdError):
    """An expert dataset file that is missing, of another version, or inconsistent."""


class SimError(EcahdError):
    """Simulator input that cannot be used: NaN velocities, a pose off the map or inside a wall,
    a configuration value out of range."""


class BagError(EcahdError):
    """A bag that cannot be written or read: an existing output directory, a bad storage name,
    a missing or unreadable bag."""
