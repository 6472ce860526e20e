"""Exception types shared by the core and the command line, and the problems that do not fail
a frame.

The core raises these, or returns :class:`Problem` values; only ``sr3d_cli.cli`` turns them into
messages and exit codes.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


class Sr3dError(Exception):
    """Base class of every error sr3d reports to a user without a traceback."""


class ConfigError(Sr3dError):
    """A configuration file or ``--set`` value is wrong (exit code 2)."""


class InputError(Sr3dError, ValueError):
    """An input file is missing, unreadable or inconsistent.

    Parameters
    ----------
    path : str or Path
        The file (or folder) at fault; it leads the message.
    problem : str
        What is wrong with it, in one line.
    """

    def __init__(self, path: str | Path, problem: str):
        self.path = str(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")


class NoTable(Sr3dError):
    """No support plane in a frame's depth where a step needs the table (the training-free
    segmenter); the stage that knows the frame's files names the one at fault."""


class FrameFailed(Sr3dError):
    """A frame ran but produced nothing it should have (a frame with objects and no grasp);
    what it wrote says why. The frame counts as failed (exit code 1)."""


class MissingExtraError(Sr3dError, ImportError):
    """An optional dependency is needed for the feature in use."""

    def __init__(self, feature: str, package: str, extra: str):
        super().__init__(
            f"{feature} needs the optional package '{package}': "
            f"pip install 'sr3d-cli[{extra}]' (or: pip install {package})"
        )


@dataclass(frozen=True)
class Problem:
    """What went wrong in a stage without failing the frame: with one object (``obj``, its id)
    or with the frame (``obj`` None). ``upstream``: it follows from an earlier stage's problem
    with that object (no mesh where reconstruct made none), which that stage reports."""

    text: str
    obj: int | None = None
    upstream: bool = False

    def __str__(self) -> str:
        return self.text if self.obj is None else f"object {self.obj}: {self.text}"
