"""The one exception family of the GroundSieve core.

Every error the core raises on purpose derives from :class:`GroundSieveError`
(itself a ``ValueError``), so callers catch one class. The Processing layer turns
it into ``QgsProcessingException(str(err))``: messages must therefore read well
on their own and name the file and the problem.
"""


class GroundSieveError(ValueError):
    """Base class of every error raised by the core."""


class InvalidParameterError(GroundSieveError):
    """A filter or workflow parameter is out of its valid range."""


class InputError(GroundSieveError):
    """The input file or arrays cannot be used (missing, unreadable, empty, ...)."""


class UnsupportedFormatError(InputError):
    """The input file is not in a format the core can read."""


class OutputError(GroundSieveError):
    """An output cannot be written where it was asked for."""


class Cancelled(GroundSieveError):
    """The caller asked to stop (``is_cancelled()`` returned True)."""


class MemoryBudgetError(InvalidParameterError):
    """A grid would need more memory than the run may use (refused before allocating it)."""


def out_of_memory(what: str, err: BaseException) -> "MemoryBudgetError":
    """A MemoryError met while ``what`` (a file, a tile) was read or worked on, in words: what to change. Reading
    a file's points under a tight ulimit -v was called a damaged or truncated file (a code reviewer)."""
    return MemoryBudgetError(f"{what}: out of memory ({err or 'MemoryError'}); give a smaller memory budget "
                             "(the log's first lines say this run's) or fewer workers, or more memory")
