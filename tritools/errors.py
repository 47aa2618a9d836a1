"""Structured input errors: the field that is wrong, and why.

:class:`FieldError` (a ValueError) names the field of an input -- a region's ``c`` or ``D``, an option's
``max_delta`` -- so that callers place the message (the command line turns an option into its flag, the
problem-file reader a field into its location ``problems[3].regions[1].D``) without parsing text.
:class:`tritools.solve.options.OptionError` is the options' kind of it.
"""
from __future__ import annotations

__all__ = ["FieldError", "ProblemTooLarge", "MISSING"]

#: the ``reason`` of a required field that was not given
MISSING = "is missing"


class FieldError(ValueError):
    """An invalid input field: ``field`` names it, ``reason`` says what is wrong (``"must be ..."``).

    ``str()`` is ``"<field> <reason>"`` unless a whole ``message`` is given (a sentence that reads better
    than the two parts)."""

    def __init__(self, field: str, reason: str, message: str | None = None):
        super().__init__(message if message is not None else f"{field} {reason}")
        self.field, self.reason, self.message = field, reason, message

    @property
    def text(self) -> str:
        """What to print after the field's location: the whole ``message`` if one was given, else ``reason``."""
        return self.message if self.message is not None else self.reason

    def __reduce__(self):                   # picklable across processes (executors)
        return type(self), (self.field, self.reason, self.message)


class ProblemTooLarge(ValueError):
    """A program refused for its size before it is built (Theorem 1 with all minors beyond its view count): the
    plan's step ends ``budget_exceeded``; any other ValueError while building a program is a numerical failure
    (numbers that overflow in the normalised frame, review 21b F2)."""
