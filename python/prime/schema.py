"""A message type's description (media/common/include/prime/common/schema.hpp)
read into a numpy dtype, and written from one (prime.Type). The text read
comes from a shared-memory segment another process wrote, so it is input:
every number is bounded by the type's size, every field must lie inside it,
nesting is bounded, and anything else is prime.Damaged naming what was
wrong."""

import re as _re

import numpy as _np

import prime as _prime

_SCALARS = {"i8": "i1", "i16": "<i2", "i32": "<i4", "i64": "<i8", "u8": "u1", "u16": "<u2", "u32": "<u4",
            "u64": "<u8", "f32": "<f4", "f64": "<f8", "bool": "?", "char": "S1"}
_MAX_DEPTH = 32


class _Parser:
    def __init__(self, text, size):
        self.text, self.size, self.at, self.depth = text, size, 0, 0

    def fail(self, what):
        raise _prime.Damaged("damaged", f"type description {self.text[:200]!r}: {what} (at {self.at})")

    def number(self, limit=None):
        start = self.at
        while self.at < len(self.text) and self.text[self.at].isdigit():
            self.at += 1
        if start == self.at or self.at - start > 12:
            self.fail("a number expected")
        n = int(self.text[start:self.at])
        if n > (self.size if limit is None else limit):
            self.fail(f"{n} is beyond the type's {self.size} bytes")
        return n

    def expect(self, char):
        if self.text[self.at:self.at + 1] != char:
            self.fail(f"{char!r} expected")
        self.at += 1

    def type(self):
        self.depth += 1
        if self.depth > _MAX_DEPTH:
            self.fail(f"nested deeper than {_MAX_DEPTH}")
        t = self.text
        if t.startswith("str", self.at):
            self.at += 3
            dtype = self.string()
        elif t.startswith("vec", self.at):
            self.at += 3
            dtype = self.vector()
        elif t.startswith("arr", self.at):
            self.at += 3
            dtype = self.array()
        elif t.startswith("{", self.at):
            dtype = self.struct()
        elif t.startswith("?", self.at):
            self.at += 1
            dtype = _np.dtype(f"V{self.number()}")
        else:
            name = next((n for n in sorted(_SCALARS, key=len, reverse=True) if t.startswith(n, self.at)), None)
            if name is None:
                self.fail("an unknown type")
            self.at += len(name)
            dtype = _np.dtype(_SCALARS[name])
        self.depth -= 1
        if dtype.itemsize > self.size:
            self.fail(f"a type of {dtype.itemsize} bytes in one of {self.size}")
        return dtype

    def element(self, n):
        """`N "," stride "(" type ")"` after the count: the element, `stride` long."""
        stride = self.number()
        self.expect("(")
        element = self.type()
        self.expect(")")
        if n * stride > self.size or element.itemsize > stride:
            self.fail(f"{n} elements of {element.itemsize} bytes, {stride} apart")
        return element if element.itemsize == stride else _padded(element, stride)

    def string(self):  # bounded_string<N>: its size (u32) and its N bytes
        n = self.number(); self.expect("@"); size_at = self.number(); self.expect(","); data_at = self.number()
        return self.fields(["size", "data"], ["<u4", f"S{n}" if n else "V0"], [size_at, data_at])

    def vector(self):  # bounded_vector<T, N>: its size (u64) and N places of T
        n = self.number(); self.expect("@"); size_at = self.number(); self.expect(",")
        data_at = self.number(); self.expect(",")
        element = self.element(n)
        return self.fields(["size", "data"], ["<u8", (element, (n,))], [size_at, data_at])

    def array(self):  # std::array<T, N>; of char: bytes (S<N>)
        n = self.number(); self.expect(",")
        element = self.element(n)
        return _np.dtype(f"S{n}") if element == _np.dtype("S1") and n > 0 else _np.dtype((element, (n,)))

    def struct(self):
        self.expect("{")
        names, formats, offsets = [], [], []
        while True:
            end = self.text.find("@", self.at)
            if end < 0:
                self.fail("a field's '@' expected")
            names.append(self.text[self.at:end])
            self.at = end + 1
            offsets.append(self.number()); self.expect(":")
            formats.append(self.type())
            if self.text[self.at:self.at + 1] == "}":
                self.at += 1
                break
            self.expect(",")
        return self.fields(names, formats, offsets)

    def fields(self, names, formats, offsets, itemsize=None):
        """A struct dtype; each field inside `itemsize` (default: as long as they reach)."""
        if len(set(names)) != len(names) or not all(n.isidentifier() for n in names):
            self.fail(f"field names {names} are not distinct identifiers")
        formats = [_np.dtype(f) for f in formats]
        reach = max(o + f.itemsize for o, f in zip(offsets, formats))
        if reach > (self.size if itemsize is None else itemsize):
            self.fail(f"fields reach byte {reach} of a type of {itemsize or self.size}")
        try:
            return _np.dtype({"names": names, "formats": formats, "offsets": offsets,
                              "itemsize": reach if itemsize is None else itemsize})
        except (ValueError, TypeError) as e:
            self.fail(str(e))


def _padded(element, stride):
    """`element` as a dtype `stride` bytes long."""
    if element.names is None:
        return _np.dtype({"names": ["value"], "formats": [element], "offsets": [0], "itemsize": stride})
    return _np.dtype({"names": list(element.names), "formats": [element.fields[n][0] for n in element.names],
                      "offsets": [element.fields[n][1] for n in element.names], "itemsize": stride})


def dtype_of(schema, size):
    """The numpy dtype of a type `size` bytes long described by `schema`, or
    None for an empty description. Raises prime.Damaged for a description
    that does not fit its size or does not parse."""
    if not schema:
        return None
    parser = _Parser(schema, size)
    dtype = parser.type()
    if parser.at != len(schema):
        parser.fail("text after the type")
    if dtype.names is None:
        return parser.fields(["value"], [dtype], [0], size)
    return parser.fields(list(dtype.names), [dtype.fields[n][0] for n in dtype.names],
                         [dtype.fields[n][1] for n in dtype.names], size)


_NAMES = {_np.dtype(v).str: k for k, v in _SCALARS.items() if k != "char"}


def description_of(dtype):
    """The description of a message laid out as `dtype` (what PRIME_DESCRIBE
    gives a C++ type of that layout; a bounded string or vector is described
    as the struct it is: its size and data fields). Raises
    prime.InvalidArgument for what a message cannot hold (objects,
    big-endian numbers) and for field names C++ cannot have; offsets are
    taken as they are, aligned or not."""
    dtype = _np.dtype(dtype)
    if dtype.subdtype is not None:
        element, shape = dtype.subdtype
        text = description_of(element)
        for n in reversed(shape):
            text = f"arr{n},{element.itemsize}({text})"
            element = _np.dtype((element, (n,)))
        return text
    if dtype.names is not None:
        bad = [n for n in dtype.names if not _re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", n)]
        if bad or not dtype.names:
            raise _prime.InvalidArgument("invalid argument", f"a message's fields are named as C++ names them "
                                                             f"(one at least): not {bad or 'none'}")
        fields = sorted(((dtype.fields[n][1], n, dtype.fields[n][0]) for n in dtype.names))
        return "{" + ",".join(f"{name}@{offset}:{description_of(field)}" for offset, name, field in fields) + "}"
    if dtype.kind == "S":
        return "char" if dtype.itemsize == 1 else f"arr{dtype.itemsize},1(char)"
    if dtype.kind == "V":
        return f"?{dtype.itemsize}"
    name = _NAMES.get(dtype.str)
    if name is None:
        raise _prime.InvalidArgument("invalid argument", f"a message cannot hold numpy {dtype} (numbers, bools, "
                                                         "bytes, arrays and structs of them, little-endian)")
    return name


def same_layout(a, b):
    """Whether dtypes `a` and `b` lay a message out alike: the same size, and
    the same description (fields by offset, arrays flat or nested, bytes as
    S<n> or as chars, a one-field struct or its field)."""
    a, b = _np.dtype(a), _np.dtype(b)
    if a == b:
        return True
    if a.itemsize != b.itemsize:
        return False
    try:
        return _canonical(a) == _canonical(b)
    except _prime.Error:
        return False


def _canonical(dtype):
    text = description_of(dtype)
    whole = _re.fullmatch(r"\{value@0:(.*)\}", text)  # dtype_of's wrapper of a type that is one value
    return whole.group(1) if whole else text


def alignment_of(dtype):
    """The alignment C++ gives a type laid out as `dtype`: its widest number's."""
    dtype = _np.dtype(dtype)
    if dtype.subdtype is not None:
        return alignment_of(dtype.subdtype[0])
    if dtype.names is not None:
        return max((alignment_of(dtype.fields[n][0]) for n in dtype.names), default=1)
    return 1 if dtype.kind in "SV" else dtype.itemsize


class Type:
    """A message type as a C++ program knows it, so that a Python end and a
    C++ end of one topic or service agree on it:

        Command = prime.Type("robot::Command", [("value", "<i8"), ("gain", "<f8")])

    `name` is the C++ type's name as the compiler spells it (namespaces
    included), `dtype` its layout (fields at the C++ offsets; itemsize its
    sizeof), `layout` its prime::layout_version. Name, size, alignment and
    layout make its fingerprint, which must equal the C++ type's: otherwise
    the two ends are refused with prime.TypeMismatch, never misread."""

    def __init__(self, name, dtype, layout=1, alignment=None):
        from prime._prime import Type as _Raw

        self.name, self.dtype, self.layout = name, _np.dtype(dtype), layout
        self.alignment = alignment_of(self.dtype) if alignment is None else alignment
        self.schema = description_of(self.dtype)
        self._raw = _Raw(name, self.dtype.itemsize, self.alignment, layout, self.schema)

    @property
    def described(self):
        """As C++ describes it: "robot::Command (16 bytes, align 8, layout 1)"."""
        return self._raw.described

    def __repr__(self):
        return f"prime.Type({self.described})"
