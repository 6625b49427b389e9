"""User-facing error kinds; the CLI turns each into an exit code (see ``pipeline.cli``)."""


class PipelineError(Exception):
    """Base of the errors a user can cause or meet; the message is one line."""

    exit_code = 2


class SpecError(PipelineError):
    """A mission spec, a claims file or an override is invalid (exit 2)."""


class LogError(PipelineError):
    """A log is missing, unreadable, incomplete or lacks a column or metadata key (exit 2)."""


class OutputError(PipelineError):
    """An output cannot be written: its folder is a file, read-only or full (exit 2)."""


class CheckFailed(PipelineError):
    """A provenance check or a claim does not hold (exit 1)."""

    exit_code = 1


class LogDamaged(CheckFailed):
    """A log fails a check against its own metadata: tampered or damaged (exit 1)."""


class RunFailed(PipelineError):
    """A mission failed or diverged; its log is written and marked so (exit 1)."""

    exit_code = 1
