"""The one line a message is shown in: what every layer's errors say to a user or a log."""
from __future__ import annotations


def one_line(said, limit: int | None = 200) -> str:
    """`said` (an exception or a text) on one line: each run of whitespace one space, at most `limit`
    characters (None: all of it); an exception that says nothing gives its type's name."""
    text = " ".join(str(said).split())
    if not text and isinstance(said, BaseException):
        text = type(said).__name__
    return text if limit is None else text[:limit]


def explain(exc: BaseException, limit: int = 200) -> str:
    """Why an operation failed, in one line: an OSError's own words (its strerror, which leaves out
    the path the caller names), else one_line(exc, limit)."""
    if isinstance(exc, OSError) and exc.strerror:
        return exc.strerror
    return one_line(exc, limit)
