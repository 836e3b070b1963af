"""Prime from Python: the Shm medium's topics and services (prime.shm).

Errors: every failure Prime reports raises a subclass of prime.Error named for
its code (prime.Timeout, prime.TypeMismatch, prime.NotFound, ...), carrying
the code and the message C++ gives: `e.code == "type mismatch"`.
"""

class Error(Exception):
    """A Prime error: .code (as C++'s prime::to_string(Errc)) and .message."""

    def __init__(self, code, message):
        super().__init__(f"{code}: {message}")
        self.code = code
        self.message = message


_errors = {}


def _error_class(code):
    """The exception class for `code` ("type mismatch" -> prime.TypeMismatch)."""
    if code not in _errors:
        name = "".join(word.capitalize() for word in code.split())
        _errors[code] = globals().get(name) or type(name, (Error,), {"__module__": __name__})
    return _errors[code]


# Every code of prime::Errc, as C++ names it, as a class one can catch.
from ._prime import codes as _codes  # noqa: E402

for _code in _codes:
    globals()[_error_class(_code).__name__] = _error_class(_code)

from .schema import Type, dtype_of  # noqa: E402
from . import shm  # noqa: E402  (it uses the errors above)
from .sync import Synced, approximate_time, exact_time, latest_of_each, sync, within_tolerance  # noqa: E402

__all__ = ["Error", "Synced", "Type", "approximate_time", "dtype_of", "exact_time", "latest_of_each", "shm", "sync",
           "within_tolerance"] + [c.__name__ for c in _errors.values()]
