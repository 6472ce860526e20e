"""Counting done / failed / skipped items and turning them into messages and the exit code."""

from __future__ import annotations

import logging
import traceback
from dataclasses import dataclass, field

import click

from sr3d_cli.errors import Sr3dError

log = logging.getLogger("sr3d")


@dataclass
class Report:
    verbose: int = 0
    done: int = 0
    failed: int = 0
    skipped: int = 0
    failures: list[str] = field(default_factory=list)

    def ok(self, n: int = 1) -> None:
        self.done += n

    def skip(self, item: str, why: str) -> None:
        self.skipped += 1
        log.info("skipped %s: %s", item, why)

    def fail(self, item: str, exc: BaseException, count: int = 1) -> None:
        """Record a failure of ``item`` (``count`` frames) with one line on stderr."""
        self.failed += count
        if isinstance(exc, Sr3dError):
            message = str(exc) if item in str(exc) else f"{item}: {exc}"
        else:
            message = f"{item}: unexpected {type(exc).__name__}: {exc}"
        self.failures.append(message)
        click.echo(f"error: {message}", err=True)
        if self.verbose:
            click.echo("".join(traceback.format_exception(exc)), err=True)

    @property
    def exit_code(self) -> int:
        return 1 if self.failed else 0

    def summary(self, what: str = "frames") -> str:
        parts = [f"{self.done} {what} done"]
        if self.skipped:
            parts.append(f"{self.skipped} skipped")
        if self.failed:
            parts.append(f"{self.failed} failed")
        return ", ".join(parts)

    def finish(self, what: str = "frames") -> None:
        log.warning("%s", self.summary(what))
        raise SystemExit(self.exit_code)
