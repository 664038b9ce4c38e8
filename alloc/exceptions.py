"""Exceptions raised by the allocation library.

Every exception derives from :class:`AllocError` and also from the built-in
exception it means, so callers can catch either.  Messages name the field and
the offending value.
"""

from __future__ import annotations

__all__ = [
    "AllocError",
    "SkippedLinesWarning",
    "ProblemError",
    "ProblemTypeError",
    "DemandError",
    "OptionError",
    "UnknownMethodError",
    "MethodTypeError",
    "SolverError",
]


class AllocError(Exception):
    """Base class of every error raised by :mod:`alloc`.

    Messages start with the field they concern (``"rate_min: ..."``); :attr:`field`
    carries it for programs (the service's problem+json), given explicitly or read from
    that leading name.
    """

    def __init__(self, *args: object, field: str | None = None) -> None:
        super().__init__(*args)
        if field is None and args and isinstance(args[0], str):
            head, sep, _ = args[0].partition(":")
            token = head.split("[", 1)[0].strip()
            if sep and token and all(part.isidentifier() for part in token.split("/")):
                field = token
        #: the input field the error concerns (``None`` when it concerns no single field)
        self.field = field


class ProblemError(AllocError, ValueError):
    """An allocation problem is malformed (shape, finiteness, limits, weights)."""


class ProblemTypeError(ProblemError, TypeError):
    """Something other than an :class:`alloc.Problem` was passed as the problem (field ``problem``)."""


class DemandError(AllocError, ValueError):
    """A demand ``v``, previous command ``u_prev`` or time step ``dt`` is invalid."""


class OptionError(AllocError, TypeError):
    """A method received an unknown option or an option of the wrong type."""


class UnknownMethodError(AllocError, ValueError):
    """The requested allocation method is not registered."""


class MethodTypeError(UnknownMethodError, TypeError):
    """The method was not given as a name (a str; field ``method``)."""


class SolverError(AllocError, RuntimeError):
    """A numerical backend failed.

    Never escapes an allocator call: the allocator catches it and returns the
    documented safe answer with ``status="fallback"``.
    """


class SkippedLinesWarning(UserWarning):
    """An importer read a file and left some of its lines out on purpose (a PX4 airframe's shell
    lines: ``. ${R}etc/init.d/rc.vtol_defaults``, ``set MAV_TYPE 22``); the message lists them."""
