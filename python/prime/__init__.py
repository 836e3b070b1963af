"""Prime from Python: the Shm medium's topics and services (prime.shm).

Errors: every failure Prime reports raises a subclass of prime.Error named for
its code (prime.Timeout, prime.TypeMismatch, prime.NotFound, ...), carrying
the code and the message C++ gives: `e.code == "type mismatch"`.
"""

import numpy as _np


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


# The codes of logic/include/prime/logic/error.hpp, as classes one can catch.
for _code in ("timeout", "stopped", "no data", "overflow", "block failed", "type mismatch", "peer dead",
              "unreachable", "in use", "qos mismatch", "no space", "not found", "damaged", "invalid argument",
              "too large", "queue full", "too many subscribers", "too many clients", "domain full", "rate limited",
              "held limit", "iteration limit", "overrun", "refused"):
    globals()[_error_class(_code).__name__] = _error_class(_code)


class _Schema:
    """Reads a type's description (prime/common/schema.hpp) into a numpy dtype."""

    _scalars = {"i8": "i1", "i16": "<i2", "i32": "<i4", "i64": "<i8", "u8": "u1", "u16": "<u2", "u32": "<u4",
                "u64": "<u8", "f32": "<f4", "f64": "<f8", "bool": "?", "char": "S1"}

    def __init__(self, text):
        self.text, self.at = text, 0

    def _number(self):
        start = self.at
        while self.at < len(self.text) and self.text[self.at].isdigit():
            self.at += 1
        if start == self.at:
            raise ValueError(f"schema {self.text!r}: a number expected at {start}")
        return int(self.text[start:self.at])

    def _expect(self, char):
        if self.text[self.at:self.at + 1] != char:
            raise ValueError(f"schema {self.text!r}: {char!r} expected at {self.at}")
        self.at += 1

    def type(self):
        t = self.text
        for prefix in ("str", "vec", "arr"):
            if t.startswith(prefix, self.at):
                self.at += 3
                return getattr(self, "_" + prefix)()
        if t.startswith("{", self.at):
            return self._struct()
        if t.startswith("?", self.at):
            self.at += 1
            return _np.dtype(f"V{self._number()}")
        for name in sorted(self._scalars, key=len, reverse=True):
            if t.startswith(name, self.at):
                self.at += len(name)
                return _np.dtype(self._scalars[name])
        raise ValueError(f"schema {t!r}: unknown type at {self.at}")

    def _str(self):  # bounded_string<N>: its size (u32) and its N bytes
        n = self._number(); self._expect("@"); size_at = self._number(); self._expect(","); data_at = self._number()
        return _np.dtype({"names": ["size", "data"], "formats": ["<u4", f"S{n}" if n else "V0"],
                          "offsets": [size_at, data_at], "itemsize": max(size_at + 4, data_at + n)})

    def _vec(self):  # bounded_vector<T, N>: its size (u64) and N places of T
        n = self._number(); self._expect("@"); size_at = self._number(); self._expect(",")
        data_at = self._number(); self._expect(","); stride = self._number()
        self._expect("("); element = self.type(); self._expect(")")
        element = self._strided(element, stride)
        return _np.dtype({"names": ["size", "data"], "formats": ["<u8", (element, (n,))],
                          "offsets": [size_at, data_at], "itemsize": max(size_at + 8, data_at + n * stride)})

    def _arr(self):  # std::array<T, N>
        n = self._number(); self._expect(","); stride = self._number()
        self._expect("("); element = self.type(); self._expect(")")
        return _np.dtype((self._strided(element, stride), (n,)))

    def _struct(self):
        self._expect("{")
        names, formats, offsets = [], [], []
        while True:
            end = self.text.index("@", self.at)
            names.append(self.text[self.at:end]); self.at = end + 1
            offsets.append(self._number()); self._expect(":")
            formats.append(self.type())
            if self.text[self.at:self.at + 1] == "}":
                self.at += 1
                break
            self._expect(",")
        size = max(o + f.itemsize for o, f in zip(offsets, formats))
        return _np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": size})

    @staticmethod
    def _strided(element, stride):
        if element.itemsize == stride:
            return element
        if element.fields is None:
            return _np.dtype({"names": ["value"], "formats": [element], "offsets": [0], "itemsize": stride})
        fields = element.fields
        return _np.dtype({"names": list(fields), "formats": [fields[n][0] for n in fields],
                          "offsets": [fields[n][1] for n in fields], "itemsize": stride})


def dtype_of(schema, size):
    """The numpy dtype of a type described by `schema`, `size` bytes long, or
    None for raw bytes (an empty schema)."""
    if not schema:
        return None
    parser = _Schema(schema)
    dtype = parser.type()
    if parser.at != len(schema):
        raise ValueError(f"schema {schema!r}: unexpected text at {parser.at}")
    if dtype.fields is None:
        return _np.dtype({"names": ["value"], "formats": [dtype], "offsets": [0], "itemsize": size})
    if dtype.itemsize > size:
        raise ValueError(f"schema {schema!r} reaches past its type's {size} bytes")
    fields = dtype.fields
    return _np.dtype({"names": list(fields), "formats": [fields[n][0] for n in fields],
                      "offsets": [fields[n][1] for n in fields], "itemsize": size})


from . import shm  # noqa: E402  (it uses the errors above)

__all__ = ["Error", "dtype_of", "shm"] + [c.__name__ for c in _errors.values()]
