"""Exception types shared by the core and the command line.

The core raises these; only ``sr3d_cli.cli`` turns them into messages and exit codes.
"""

from __future__ import annotations

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
