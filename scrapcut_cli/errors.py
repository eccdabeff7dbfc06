"""One root exception; each package raises its own subclass.

The command line turns a :class:`ScrapcutError` into one line on stderr and exit code 1.
Anything else is a bug and keeps its traceback.
"""


class ScrapcutError(Exception):
    """A known failure the user can act on; the message is one line naming the problem."""


class FileError(ScrapcutError):
    """An input or output the file system cannot serve as asked: not a regular file, a link
    loop, a write that did not reach the disk whole."""


class ConfigError(ScrapcutError):
    """Bad parameter values or an unreadable configuration file."""


class RecordingError(ScrapcutError):
    """Unreadable recording, missing topic, broken TF tree, bad image encoding."""


class PerceptionError(ScrapcutError):
    """No paint found, empty clouds."""


class FittingError(ScrapcutError):
    """A curve could not be fitted (too few points, skeleton broken into pieces)."""


class ToolpathError(ScrapcutError):
    """Set-points could not be generated (no surface around the curve, unknown material)."""


class ExplorationError(ScrapcutError):
    """The next-view planner cannot go on."""


class EvaluationError(ScrapcutError):
    """No reference, unreadable path file."""


class PipelineError(ScrapcutError):
    """A job, batch or reproduce run cannot start: bad inputs, grid or manifest, no cluster."""


class SimError(ScrapcutError):
    """Unknown object, infeasible robot pose, simulator failure."""


class MotionError(ScrapcutError):
    """No joint trajectory: unreadable URDF or tool mount, a path the robot cannot follow."""


class CalibrationError(ScrapcutError):
    """The camera mount and clock offset cannot be estimated (no overlapping views, bad file)."""
