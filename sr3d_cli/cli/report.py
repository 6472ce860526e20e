"""Counting done / failed / skipped items and turning them into messages and the exit code.

Messages go through :func:`say`, which prints above a progress bar instead of into it. The
closing summary names every failed item with its one-line reason; ``--report FILE`` writes the
same as JSON.
"""

from __future__ import annotations

import logging
import sys
import traceback
from dataclasses import dataclass, field

import click
from tqdm import tqdm

from sr3d_cli.errors import Sr3dError

log = logging.getLogger("sr3d")

INTERRUPTED = 130  # the shell's code for a run stopped by Ctrl-C (128 + SIGINT)


def say(message: str) -> None:
    """One message on stderr, above any progress bar (tqdm clears and redraws it)."""
    tqdm.write(message, file=sys.stderr)


class TqdmHandler(logging.Handler):
    """Log records written with :func:`say`, so they never share a line with a progress bar."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            say(self.format(record))
        except Exception:  # pragma: no cover - logging must not raise
            self.handleError(record)


@dataclass
class Report:
    verbose: int = 0
    done: int = 0
    failed: int = 0
    skipped: int = 0
    failures: list[str] = field(default_factory=list)
    items: list[dict] = field(default_factory=list)
    interrupted: bool = False

    def ok(self, n: int = 1) -> None:
        self.done += n

    def skip(self, item: str, why: str) -> None:
        self.skipped += 1
        log.info("skipped %s: %s", item, why)

    def fail(self, item: str, exc: BaseException | str, count: int = 1,
             details: str | None = None) -> None:
        """Record a failure of ``item`` (``count`` frames) with one line on stderr;
        ``details`` (a traceback) is shown with -v only."""
        self.failed += count
        if isinstance(exc, str):
            reason = exc
        elif isinstance(exc, Sr3dError):
            reason = str(exc)
        else:
            reason = f"unexpected {type(exc).__name__}: {exc}"
        reason = " ".join(reason.split()) or type(exc).__name__
        message = reason if reason.startswith(item) else f"{item}: {reason}"
        self.failures.append(message)
        self.items.append({"item": item, "frames": count, "reason": message})
        say(f"error: {message}")
        if self.verbose:
            if details is None and isinstance(exc, BaseException):
                details = "".join(traceback.format_exception(exc))
            if details:
                say(details.rstrip())

    @property
    def exit_code(self) -> int:
        return INTERRUPTED if self.interrupted else (1 if self.failed else 0)

    def summary(self, what: str = "frames") -> str:
        parts = [f"{self.done} {what} done"]
        if self.skipped:
            parts.append(f"{self.skipped} skipped")
        if self.failed:
            parts.append(f"{self.failed} failed")
        lines = [", ".join(parts) + (" (interrupted)" if self.interrupted else "")]
        lines += [f"  failed: {message}" for message in self.failures]
        return "\n".join(lines)

    def to_json(self, what: str = "frames") -> dict:
        return {"unit": what, "done": self.done, "failed": self.failed,
                "skipped": self.skipped, "interrupted": self.interrupted,
                "exit_code": self.exit_code, "failures": self.items}

    def finish(self, what: str = "frames") -> None:
        """Print the summary (failures even with -q), write ``--report``, exit with the code."""
        if self.failed or self.interrupted:
            say(self.summary(what))
        else:
            log.warning("%s", self.summary(what))
        path = click.get_current_context().meta.get("sr3d.report")
        if path:
            from sr3d_cli.io.atomic import write_json

            try:
                write_json(path, self.to_json(what))
            except OSError as exc:
                say(f"error: {path}: cannot write the report ({exc.strerror or exc})")
                raise SystemExit(2) from None
        raise SystemExit(self.exit_code)
