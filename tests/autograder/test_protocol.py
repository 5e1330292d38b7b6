"""Tests of the boundary (codec, frames, values, limits): round-trips, hostile values, forged trees, frames."""

from __future__ import annotations

import ast
import itertools
import json
import math
import socket
import struct
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from autograder.boundary import codec, frames, limits, values
from autograder.boundary.codec import MAX_STR_CHARS, decode, encode, encode_result
from autograder.boundary.frames import recv_frame, recv_message, send_frame, send_message
from autograder.boundary.limits import MAX_DEPTH
from autograder.boundary.values import CallableRef, Unsupported, replace_refs
from autograder.errors import ProtocolError

MiB = 2**20


# --------------------------------------------------------------------------
# helpers


def roundtrip(value, **kwargs):
    tree, buffers = encode(value, **kwargs)
    json.dumps(tree, allow_nan=False)  # the tree is plain JSON
    return decode(tree, buffers)


def assert_same(got, expected, where="value"):
    """Equal values of exactly the same types; arrays fresh, base-class and writeable."""
    assert type(got) is type(expected), f"{where}: {type(got)} != {type(expected)}"
    if isinstance(expected, np.ndarray):
        assert got.dtype == expected.dtype and got.shape == expected.shape, where
        assert np.array_equal(got, expected, equal_nan=got.dtype.kind in "fc"), where
        assert got.flags.writeable and got.flags.c_contiguous and got.base is None, where
        assert not np.shares_memory(got, expected), where
    elif isinstance(expected, float):
        assert (math.isnan(got) and math.isnan(expected)) or (
            got == expected and math.copysign(1, got) == math.copysign(1, expected)
        ), f"{where}: {got!r} != {expected!r}"
    elif isinstance(expected, complex):
        assert_same(got.real, expected.real, where + ".real")
        assert_same(got.imag, expected.imag, where + ".imag")
    elif isinstance(expected, (list, tuple)):
        assert len(got) == len(expected), where
        for i, (g, e) in enumerate(zip(got, expected)):
            assert_same(g, e, f"{where}[{i}]")
    elif isinstance(expected, dict):
        assert list(got) == list(expected), where
        for k in expected:
            assert_same(got[k], expected[k], f"{where}[{k!r}]")
    else:
        assert got == expected, f"{where}: {got!r} != {expected!r}"


@pytest.fixture
def pair():
    a, b = socket.socketpair()
    yield a, b
    a.close()
    b.close()


def send_in_thread(fn):
    """Run ``fn`` in a thread (a socketpair's buffer is small); return a join function
    that re-raises the thread's exception."""
    errors = []

    def run():
        try:
            fn()
        except BaseException as exc:  # reported by join()
            errors.append(exc)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()

    def join():
        thread.join(30)
        if errors:
            raise errors[0]

    return join


def raw_frame(header: bytes | str, *payload: bytes) -> bytes:
    if isinstance(header, str):
        header = header.encode()
    return struct.pack(">I", len(header)) + header + b"".join(payload)


# --------------------------------------------------------------------------
# round-trips

SCALARS = {
    "none": None,
    "true": True,
    "false": False,
    "zero": 0,
    "negative": -17,
    "int64-overflow": 2**63,
    "int-1024-bits": 2**1024 - 1,
    "int-tagged": 2**1024,
    "int-negative-tagged": -(3**4000),
    "float": 1.5,
    "negative-zero": -0.0,
    "nan": math.nan,
    "inf": math.inf,
    "-inf": -math.inf,
    "max-float": 1.7976931348623157e308,
    "subnormal": 5e-324,
    "complex": complex(1, -2),
    "complex-nonfinite": complex(math.nan, -math.inf),
    "empty-str": "",
    "unicode": "héllo ☃ \U0001f600",
    "lone-surrogate": "\ud800x",
    "empty-bytes": b"",
    "bytes": bytes(range(256)),
}


@pytest.mark.parametrize("value", SCALARS.values(), ids=SCALARS.keys())
def test_scalars_round_trip(value):
    assert_same(roundtrip(value), value)


def test_containers_round_trip():
    value = {
        "list": [1, [2, [3, []]], ()],
        "tuple": (1, (2.5, "x"), [None]),
        "empty": {},
        "$t": "a key that looks like a tag",
        "nested": {"$t": {"$t": ("tuple?",)}, "z": [{"a": b"\x00"}]},
        "order": {"b": 1, "a": 2},
        "array in tuple": (np.arange(3), {"k": np.eye(2)}),
    }
    assert_same(roundtrip(value), value)


def test_dict_with_tag_key_is_escaped():
    tree, _ = encode({"$t": "nd", "buf": 0})
    assert tree == {"$t": "dict", "items": [["$t", "nd"], ["buf", 0]]}


ARRAYS = {
    "float64-2d": np.arange(12.0).reshape(3, 4),
    "empty": np.zeros(0),
    "empty-2d": np.zeros((0, 3), dtype=np.int32),
    "zero-d": np.array(2.5),
    "zero-d-bool": np.array(True),
    "transposed": np.arange(12.0).reshape(3, 4).T,
    "strided": np.arange(20, dtype=np.int16)[::3],
    "negative-stride": np.arange(10.0)[::-1],
    "fortran": np.asfortranarray(np.arange(6).reshape(2, 3)),
    "big-endian-f8": np.arange(5, dtype=">f8"),
    "big-endian-i2": np.array([[1, -2], [300, 4]], dtype=">i2"),
    "complex64": np.array([1 + 2j, np.nan + 1j], dtype=np.complex64),
    "complex128-big-endian": np.array([1 - 1j, 3j], dtype=">c16"),
    "bool": np.array([[True, False], [False, True]]),
    "uint8": np.arange(256, dtype=np.uint8),
    "uint64": np.array([2**64 - 1], dtype=np.uint64),
    "float16": np.array([0.5, np.inf], dtype=np.float16),
    "longdouble": np.array([1.0, 1e-300], dtype=np.longdouble),
    "nan-inf": np.array([np.nan, np.inf, -np.inf, -0.0]),
    "five-dims": np.ones((1, 2, 1, 2, 1)),
}


@pytest.mark.parametrize("array", ARRAYS.values(), ids=ARRAYS.keys())
def test_arrays_round_trip(array):
    got = roundtrip(array)
    assert_same(got, array)
    got[...] = 0  # writeable
    assert got.dtype.str == array.dtype.str  # byte order kept


def test_array_tree_shape():
    tree, buffers = encode(np.arange(6.0).reshape(3, 2))
    assert tree == {"$t": "nd", "dtype": "<f8", "shape": [3, 2], "buf": 0}
    assert bytes(buffers[0]) == np.arange(6.0).tobytes()


def test_contiguous_arrays_are_not_copied_on_encode():
    array = np.arange(1000.0)
    _, buffers = encode(array)
    assert np.shares_memory(np.frombuffer(buffers[0], dtype=np.uint8), array)


@pytest.mark.parametrize(
    "scalar, expected",
    [
        (np.float64(1.5), 1.5),
        (np.float32(0.25), 0.25),
        (np.float16(np.inf), math.inf),
        (np.longdouble(2.0), 2.0),
        (np.int8(-3), -3),
        (np.uint64(2**64 - 1), 2**64 - 1),
        (np.intc(7), 7),
        (np.longlong(8), 8),
        (np.bool_(True), True),
        (np.complex64(1 + 1j), 1 + 1j),
        (np.clongdouble(2j), 2j),
    ],
    ids=lambda v: type(v).__name__,
)
def test_numpy_scalars_become_python_scalars(scalar, expected):
    assert_same(roundtrip(scalar), expected)


def test_unsupported_round_trips():
    value = Unsupported(type="x.Y", repr="<Y>", reason="because")
    assert roundtrip(value) == value


_DTYPES = st.sampled_from(["<f8", ">f8", "<f4", "<i8", ">i4", "|u1", "|b1", "<c16", ">c8"])
_ARRAYS = hnp.arrays(dtype=_DTYPES, shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4))
_SCALARS = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.floats()
    | st.complex_numbers()
    | st.text(max_size=20)
    | st.binary(max_size=20)
)
_KEYS = st.sampled_from(["$t", "v", "bufs", "items"]) | st.text(max_size=8)
_VALUES = st.recursive(
    _SCALARS | _ARRAYS,
    lambda children: st.lists(children, max_size=4)
    | st.lists(children, max_size=4).map(tuple)
    | st.dictionaries(_KEYS, children, max_size=4),
    max_leaves=15,
)


@settings(max_examples=150, deadline=None)
@given(_VALUES)
def test_any_plain_value_round_trips(value):
    assert_same(roundtrip(value), value)


# --------------------------------------------------------------------------
# hostile values


class EqualsEverything(np.ndarray):
    def __eq__(self, other):
        return True


class SneakyList(list):
    def __iter__(self):
        raise RuntimeError("no iteration")

    def __len__(self):
        raise RuntimeError("no len")


class OddInt(int):
    def __eq__(self, other):
        return True

    def __hash__(self):
        return 0


class Liar:
    @property
    def __class__(self):
        return list

    def __repr__(self):
        raise ValueError("repr is hostile")


class RaisingClass:
    @property
    def __class__(self):
        raise RuntimeError("no class for you")


class GetattrRaises:
    def __getattr__(self, name):
        raise RuntimeError(f"no {name}")

    def __getattribute__(self, name):
        raise RuntimeError(f"no {name}")


class ReprExits:
    def __repr__(self):
        raise SystemExit(3)


class ReprNotStr:
    def __repr__(self):
        return 42


class StrSubclassRepr:
    class S(str):
        def __len__(self):
            raise RuntimeError("len")

        def __getitem__(self, item):
            raise RuntimeError("getitem")

    def __repr__(self):
        return self.S("x" * 1000)


class HostileMeta(type):
    def __hash__(cls):
        raise RuntimeError("unhashable class")

    def __eq__(cls, other):
        raise RuntimeError("no eq")


class WithHostileMeta(metaclass=HostileMeta):
    pass


class WeirdModule:
    __module__ = 42  # not a str


class FakeFigure:
    pass


FakeFigure.__module__ = "matplotlib.figure"
FakeFigure.__name__ = FakeFigure.__qualname__ = "Figure"


def make_matrix():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        return np.matrix([[1, 2]])


def recursive_list():
    x = [1]
    x.append(x)
    return x


HOSTILE = {
    "ndarray-subclass-eq-true": lambda: np.arange(3).view(EqualsEverything),
    "matrix": lambda: make_matrix(),
    "masked-array": lambda: np.ma.masked_array([1, 2], mask=[0, 1]),
    "object-array": lambda: np.array([1, "a"], dtype=object),
    "str-array": lambda: np.array(["a", "b"]),
    "datetime-array": lambda: np.array(["2020-01-01"], dtype="datetime64[D]"),
    "structured-array": lambda: np.zeros(2, dtype=[("a", "<f8"), ("b", "<i4")]),
    "void-scalar": lambda: np.zeros(1, dtype="V4")[0],
    "datetime-scalar": lambda: np.datetime64("2020-01-01"),
    "str-scalar": lambda: np.str_("a"),
    "list-subclass": lambda: SneakyList([1, 2]),
    "int-subclass": lambda: OddInt(3),
    "bool-like-int-subclass": lambda: type("MyBool", (int,), {})(1),
    "float-subclass-of-float64": lambda: type("F", (np.float64,), {})(1.0),
    "str-subclass": lambda: type("S", (str,), {})("x"),
    "dict-subclass": lambda: type("D", (dict,), {})(a=1),
    "liar-with-raising-repr": Liar,
    "class-property-raises": RaisingClass,
    "getattr-raises": GetattrRaises,
    "repr-exits": ReprExits,
    "repr-not-str": ReprNotStr,
    "repr-str-subclass": StrSubclassRepr,
    "hostile-metaclass": WithHostileMeta,
    "non-str-module": WeirdModule,
    "generator": lambda: (i for i in itertools.count()),
    "iterator": lambda: itertools.count(),
    "dict-int-keys": lambda: {1: "a", 2: "b"},
    "dict-mixed-keys": lambda: {"a": 1, (1, 2): 2},
    "set": lambda: {1, 2},
    "bytearray": lambda: bytearray(b"ab"),
    "memoryview": lambda: memoryview(b"ab"),
    "function": lambda: (lambda: 1),
    "module": lambda: np,
    "class": lambda: int,
    "huge-int": lambda: 10**10_001,
    "huge-str": lambda: "x" * (MAX_STR_CHARS + 1),
    "huge-broadcast-view": lambda: np.broadcast_to(np.float64(1), (10**12,)),
    "memmap-subclass": lambda: np.zeros(2).view(np.memmap),
    "fake-figure": FakeFigure,
}


@pytest.mark.parametrize("make", HOSTILE.values(), ids=HOSTILE.keys())
def test_hostile_values_come_back_unsupported(make):
    value = make()
    tree, buffers = encode(value)
    got = decode(tree, buffers)
    assert isinstance(got, Unsupported), got
    assert got.type and got.reason
    assert len(got.repr) <= 300


def test_unsupported_names_the_real_type_not_the_lying_class():
    got = roundtrip(Liar())
    assert got.type.endswith("Liar")
    assert "repr raised ValueError" in got.repr


def test_hostile_items_inside_containers_stay_local():
    value = [1, SneakyList(), {"a": OddInt(2), "b": np.float64(2.0)}, (Liar(), 3.0)]
    got = roundtrip(value)
    assert got[0] == 1 and type(got[1]) is Unsupported
    assert type(got[2]["a"]) is Unsupported and got[2]["b"] == 2.0
    assert type(got[3][0]) is Unsupported and got[3][1] == 3.0


def test_a_repr_that_mutates_its_container_does_not_break_encoding():
    class Grows:
        def __init__(self, target):
            self.target = target

        def __repr__(self):
            self.target.append(Grows(self.target))
            if isinstance(self.target, dict):
                self.target[len(self.target)] = 0
            return "grows"

    items: list = []
    items.append(Grows(items))
    assert type(roundtrip(items)[0]) is Unsupported
    mapping: dict = {}
    mapping["a"] = Grows([])
    mapping["b"] = Grows(mapping)  # type: ignore[arg-type]
    got = roundtrip(mapping)
    assert type(got["a"]) is Unsupported


def test_a_failing_item_leaves_no_stray_buffers():
    class MutatesDuringIteration:
        def __init__(self, target):
            self.target = target

        def __repr__(self):
            self.target["new"] = 1
            return "x"

    inner = {"array": np.arange(3)}
    inner["evil"] = MutatesDuringIteration(inner)
    tree, buffers = encode([np.zeros(2), inner])
    got = decode(tree, buffers)  # every buffer is referenced exactly once
    assert_same(got[0], np.zeros(2))


def test_a_generator_is_not_consumed():
    gen = (i for i in range(3))
    roundtrip(gen)
    assert list(gen) == [0, 1, 2]


def test_figure_without_an_encoder_is_unsupported():
    got = roundtrip(FakeFigure())
    assert "figure encoder" in got.reason


def test_a_raising_figure_encoder_gives_unsupported():
    def encoder(fig):
        raise RuntimeError("boom")

    got = roundtrip(FakeFigure(), figure_encoder=encoder)
    assert type(got) is Unsupported and "RuntimeError: boom" in got.reason


def test_a_figure_encoder_returning_junk_gives_unsupported():
    got = roundtrip(FakeFigure(), figure_encoder=lambda fig: {"axes": []})
    assert type(got) is Unsupported


def test_figure_node_decodes_to_a_plain_dict():
    def encoder(fig):
        return {"$t": "figure", "axes": [{"x": np.arange(3.0)}], "png": b"\x89PNG", "truncated": False}

    got = roundtrip([FakeFigure()], figure_encoder=encoder)
    assert list(got[0]) == ["$t", "axes", "png", "truncated"] and got[0]["$t"] == "figure"
    assert got[0]["png"] == b"\x89PNG"
    assert_same(got[0]["axes"][0]["x"], np.arange(3.0))


# --------------------------------------------------------------------------
# limits


def nested(depth):
    value: list = []
    for _ in range(depth - 1):
        value = [value]
    return value


def test_depth_limit_is_inclusive():
    assert_same(roundtrip(nested(MAX_DEPTH)), nested(MAX_DEPTH))
    with pytest.raises(ProtocolError, match="nested deeper than 32"):
        encode(nested(MAX_DEPTH + 1))


def test_recursive_list_hits_the_depth_limit():
    with pytest.raises(ProtocolError, match="nested deeper"):
        encode(recursive_list())


def test_item_limit():
    with pytest.raises(ProtocolError, match="more than 10 items"):
        encode(list(range(10)), max_items=10)
    assert roundtrip(list(range(9)), max_items=10) == list(range(9))


def test_encode_leaves_given_buffers_untouched_on_error():
    buffers = [b"keep"]
    with pytest.raises(ProtocolError):
        encode([np.arange(3), recursive_list()], buffers=buffers)
    assert buffers == [b"keep"]


@pytest.mark.parametrize(
    "value, reason",
    [
        (recursive_list(), "nested deeper"),
        (nested(MAX_DEPTH), "nested deeper"),  # encode_result leaves room for an envelope
        (list(range(MAX_DEPTH)) * 40_000, "items"),
    ],
    ids=["recursive", "deep", "many-items"],
)
def test_encode_result_turns_limits_into_unsupported(value, reason):
    tree, buffers = encode_result(value)
    got = decode(tree, buffers)
    assert type(got) is Unsupported and reason in got.reason
    assert buffers == []


def test_encode_result_size_limit():
    tree, buffers = encode_result([np.zeros(1000), np.zeros(1000)], max_bytes=10_000)
    got = decode(tree, buffers)
    assert type(got) is Unsupported and "limit" in got.reason and buffers == []


def test_encode_result_passes_ordinary_values():
    value = {"hull": np.arange(6.0).reshape(3, 2), "n": 3}
    tree, buffers = encode_result(value)
    assert_same(decode(tree, buffers), value)


def test_encode_result_never_raises_on_hostile_values():
    for make in HOSTILE.values():
        tree, buffers = encode_result([make(), recursive_list()])
        assert type(decode(tree, buffers)) is Unsupported


# --------------------------------------------------------------------------
# decode rejects forged trees

F8 = np.arange(2.0).tobytes()
FORGED = {
    "object-dtype": ({"$t": "nd", "dtype": "|O", "shape": [2], "buf": 0}, [F8], "dtype"),
    "object-dtype-8": ({"$t": "nd", "dtype": "|O8", "shape": [2], "buf": 0}, [F8], "dtype"),
    "structured-dtype": ({"$t": "nd", "dtype": "[('a', '<f8')]", "shape": [2], "buf": 0}, [F8], "dtype"),
    "subarray-dtype": ({"$t": "nd", "dtype": "('<f8', (2,))", "shape": [1], "buf": 0}, [F8], "dtype"),
    "comma-dtype": ({"$t": "nd", "dtype": "<f8,<f8", "shape": [1], "buf": 0}, [F8], "dtype"),
    "void-dtype": ({"$t": "nd", "dtype": "|V8", "shape": [2], "buf": 0}, [F8], "dtype"),
    "datetime-dtype": ({"$t": "nd", "dtype": "<M8[s]", "shape": [2], "buf": 0}, [F8], "dtype"),
    "str-dtype": ({"$t": "nd", "dtype": "<U2", "shape": [2], "buf": 0}, [F8], "dtype"),
    "unknown-dtype": ({"$t": "nd", "dtype": "<c4", "shape": [4], "buf": 0}, [F8], "dtype"),
    "dtype-not-str": ({"$t": "nd", "dtype": 8, "shape": [2], "buf": 0}, [F8], "dtype"),
    "shape-mismatch": ({"$t": "nd", "dtype": "<f8", "shape": [3], "buf": 0}, [F8], "needs 24 bytes"),
    "negative-shape": ({"$t": "nd", "dtype": "<f8", "shape": [-2], "buf": 0}, [F8], "non-negative"),
    "negative-shape-product": ({"$t": "nd", "dtype": "<f8", "shape": [-1, -2], "buf": 0}, [F8], "non-negative"),
    "bool-in-shape": ({"$t": "nd", "dtype": "<f8", "shape": [True, 2], "buf": 0}, [F8], "non-negative ints"),
    "float-in-shape": ({"$t": "nd", "dtype": "<f8", "shape": [2.0], "buf": 0}, [F8], "non-negative ints"),
    "shape-not-list": ({"$t": "nd", "dtype": "<f8", "shape": 2, "buf": 0}, [F8], "shape"),
    "too-many-dims": ({"$t": "nd", "dtype": "<f8", "shape": [1] * 33, "buf": 0}, [b""], "shape"),
    "huge-zero-size-shape": ({"$t": "nd", "dtype": "<f8", "shape": [0, 2**70], "buf": 0}, [b""], "cannot be built"),
    "buffer-index-out-of-range": ({"$t": "nd", "dtype": "<f8", "shape": [2], "buf": 1}, [F8], "buffer index"),
    "buffer-index-bool": ({"$t": "bytes", "buf": False}, [F8], "buffer index"),
    "buffer-index-negative": ({"$t": "bytes", "buf": -1}, [F8], "buffer index"),
    "buffer-used-twice": ([{"$t": "bytes", "buf": 0}, {"$t": "bytes", "buf": 0}], [F8], "twice"),
    "buffer-unused": ([1], [F8], "not referenced"),
    "buffer-not-bytes": ({"$t": "bytes", "buf": 0}, ["abc"], "bytes-like"),
    "missing-key": ({"$t": "nd", "dtype": "<f8", "shape": [2]}, [F8], "needs keys"),
    "extra-key": ({"$t": "nd", "dtype": "<f8", "shape": [2], "buf": 0, "type": "x"}, [F8], "needs keys"),
    "unknown-tag": ({"$t": "pickle", "data": "gASV"}, [], "unknown tag"),
    "tag-not-str": ({"$t": 1, "items": []}, [], "unknown tag"),
    "tag-is-dict": ({"$t": {"$t": "tuple"}, "items": []}, [], "unknown tag"),
    "tuple-items-not-list": ({"$t": "tuple", "items": {"a": 1}}, [], "items must be a list"),
    "dict-pair-not-list": ({"$t": "dict", "items": [["a", 1, 2]]}, [], "pairs"),
    "dict-key-not-str": ({"$t": "dict", "items": [[1, 1]]}, [], "pairs"),
    "dict-duplicate-key": ({"$t": "dict", "items": [["a", 1], ["a", 2]]}, [], "twice"),
    "float-tag-bad": ({"$t": "float", "v": "1.5"}, [], "float"),
    "float-tag-number": ({"$t": "float", "v": 1.5}, [], "float"),
    "complex-str-part": ({"$t": "complex", "re": "1", "im": 0.0}, [], "complex"),
    "complex-nan-part": ({"$t": "complex", "re": math.nan, "im": 0.0}, [], "complex"),
    "int-tag-decimal": ({"$t": "int", "hex": "12345"}, [], "hex"),
    "int-tag-huge": ({"$t": "int", "hex": "0x" + "f" * 9000}, [], "hex"),
    "untagged-big-int": (2**2000, [], "1024 bits"),
    "untagged-nan": (math.nan, [], "non-finite"),
    "untagged-inf-in-list": ([1.0, math.inf], [], "non-finite"),
    "unsupported-not-str": ({"$t": "unsupported", "type": 1, "repr": "x"}, [], "must be a str"),
    "unsupported-extra": ({"$t": "unsupported", "type": "a", "repr": "x", "code": "x"}, [], "needs keys"),
    "figure-without-png": ({"$t": "figure", "axes": []}, [], "png"),
    "figure-png-not-bytes": ({"$t": "figure", "axes": [], "png": "\x89PNG"}, [], "png"),
    "figure-axes-not-list": ({"$t": "figure", "axes": {}, "png": {"$t": "bytes", "buf": 0}}, [b""], "axes"),
    "tuple-node": ((1, 2), [], "not JSON"),
    "set-node": ({1, 2}, [], "not JSON"),
    "object-node": (object(), [], "not JSON"),
    "bytes-node": (b"abc", [], "not JSON"),
    "non-str-key": ({1: 2}, [], "not a str"),
    "long-str": ("x" * (MAX_STR_CHARS + 1), [], "exceeds"),
}


@pytest.mark.parametrize("tree, buffers, match", FORGED.values(), ids=FORGED.keys())
def test_decode_rejects_forged_trees(tree, buffers, match):
    with pytest.raises(ProtocolError, match=match):
        decode(tree, buffers)


@pytest.mark.parametrize("wrap", [lambda v: [v], lambda v: {"a": v}, lambda v: {"$t": "tuple", "items": [v]}])
def test_decode_rejects_10000_levels_of_nesting(wrap):
    tree: object = 0
    for _ in range(10_000):
        tree = wrap(tree)
    with pytest.raises(ProtocolError, match="nested deeper"):
        decode(tree, [])


def test_decode_item_limit():
    with pytest.raises(ProtocolError, match="items"):
        decode(list(range(100)), [], max_items=50)


def test_decoded_arrays_do_not_alias_the_buffers():
    buffer = bytearray(np.arange(3.0).tobytes())
    got = decode({"$t": "nd", "dtype": "<f8", "shape": [3], "buf": 0}, [buffer])
    buffer[:] = bytes(len(buffer))
    assert_same(got, np.arange(3.0))


# --------------------------------------------------------------------------
# frames


def test_message_round_trip_over_a_socket(pair):
    a, b = pair
    value = {"args": (np.arange(6.0).reshape(2, 3), [1, 2.5, math.nan]), "name": "convex_hull", "blob": b"\x00" * 10}
    join = send_in_thread(lambda: [send_message(a, value), send_message(a, [value, None])])
    assert_same(recv_message(b, timeout=10), value)
    assert_same(recv_message(b, timeout=10), [value, None])
    join()


def test_fifty_megabyte_array(pair):
    a, b = pair
    array = np.arange(50 * MiB // 8, dtype=np.float64)
    join = send_in_thread(lambda: send_message(a, {"big": array}))
    got = recv_message(b, timeout=20)
    join()
    assert_same(got["big"], array)


def test_frame_over_the_limit_is_refused_before_reading_the_payload(pair):
    a, b = pair
    a.sendall(raw_frame(json.dumps({"v": {"$t": "bytes", "buf": 0}, "bufs": [80 * MiB]})))
    # no payload follows: reading it would block until the timeout
    start = time.monotonic()
    with pytest.raises(ProtocolError, match="frame of 80.* MiB exceeds the 64 MiB limit"):
        recv_message(b, timeout=5)
    assert time.monotonic() - start < 2


def test_header_over_the_limit_is_refused(pair):
    a, b = pair
    a.sendall(struct.pack(">I", 2**31))
    with pytest.raises(ProtocolError, match="exceeds"):
        recv_message(b, timeout=5)


def test_small_max_bytes_on_receive(pair):
    a, b = pair
    join = send_in_thread(lambda: send_message(a, np.zeros(1000)))
    with pytest.raises(ProtocolError, match="exceeds the 1 KiB limit"):
        recv_message(b, max_bytes=1024, timeout=5)
    b.close()  # the stream is out of step: close it
    join()


def test_sender_refuses_an_oversized_frame_before_sending(pair):
    a, b = pair
    with pytest.raises(ProtocolError, match="exceeds"):
        send_message(a, np.zeros(1000), max_bytes=1024)
    with pytest.raises(TimeoutError):
        recv_message(b, timeout=0.1)  # nothing was sent


@pytest.mark.parametrize("cut", [0, 2, 6, 30, -5], ids=["nothing", "in-length", "in-header", "in-prefix", "in-payload"])
def test_truncated_frame_raises_eof(pair, cut):
    a, b = pair
    frame = raw_frame(json.dumps({"v": {"$t": "bytes", "buf": 0}, "bufs": [16]}), struct.pack(">Q", 16), b"x" * 16)
    if cut == 30:
        cut = 4 + len(json.dumps({"v": {"$t": "bytes", "buf": 0}, "bufs": [16]})) + 3
    a.sendall(frame[:cut])
    a.close()
    with pytest.raises(EOFError, match="connection closed"):
        recv_message(b, timeout=5)


def test_timeout_raises_and_restores_the_socket_timeout(pair):
    a, b = pair
    b.settimeout(None)
    start = time.monotonic()
    with pytest.raises(TimeoutError):
        recv_message(b, timeout=0.2)
    assert 0.15 < time.monotonic() - start < 2
    assert b.gettimeout() is None


def test_timeout_is_a_deadline_for_the_whole_frame(pair):
    a, b = pair
    frame = raw_frame(json.dumps({"v": [1], "bufs": []}))

    def trickle():
        for byte in frame[:-1]:
            a.sendall(bytes([byte]))
            time.sleep(0.02)

    join = send_in_thread(trickle)
    with pytest.raises(TimeoutError):
        recv_message(b, timeout=0.3)
    join()



class _CountingSocket(socket.socket):
    """A socket that counts the changes of its timeout (each one is a system call)."""

    changes = 0

    def settimeout(self, value: float | None) -> None:
        type(self).changes += 1
        super().settimeout(value)


def test_a_frame_that_is_there_is_read_without_touching_the_socket_mode(pair):
    a, b = pair
    counted = _CountingSocket(fileno=b.detach())
    try:
        _CountingSocket.changes = 0
        value = {"args": [np.arange(6.0).reshape(3, 2)], "name": "hull"}
        send_message(a, value)
        assert_same(recv_message(counted, timeout=5), value)
        assert _CountingSocket.changes == 0 and counted.gettimeout() is None
        # A frame that arrives in pieces waits with the deadline, then the mode is put back.
        frame = raw_frame(json.dumps({"v": [1], "bufs": []}))
        a.sendall(frame[:3])
        join = send_in_thread(lambda: (time.sleep(0.1), a.sendall(frame[3:])))
        assert recv_message(counted, timeout=5) == [1]
        join()
        assert _CountingSocket.changes >= 2 and counted.gettimeout() is None
        # A socket with a timeout of its own keeps it, and a missing frame still times out.
        counted.settimeout(7.0)
        send_message(a, value)
        assert_same(recv_message(counted, timeout=5), value)
        assert counted.gettimeout() == 7.0
        with pytest.raises(TimeoutError):
            recv_message(counted, timeout=0.2)
        assert counted.gettimeout() == 7.0
    finally:
        counted.close()

BAD_FRAMES = {
    "nan-literal": (raw_frame('{"v": [NaN], "bufs": []}'), "NaN"),
    "infinity-literal": (raw_frame('{"v": -Infinity, "bufs": []}'), "Infinity"),
    "overflowing-float": (raw_frame('{"v": 1e400, "bufs": []}'), "non-finite"),
    "long-int-literal": (raw_frame('{"v": ' + "9" * 400 + ', "bufs": []}'), "int"),
    "not-json": (raw_frame("{v: 1}"), "not valid JSON"),
    "not-utf8": (raw_frame(b'{"v": "\xff", "bufs": []}'), "UTF-8"),
    "not-an-object": (raw_frame("[1, 2]"), "'v' and 'bufs'"),
    "extra-header-key": (raw_frame('{"v": 1, "bufs": [], "x": 1}'), "'v' and 'bufs'"),
    "duplicate-key": (raw_frame('{"v": {"a": 1, "a": 2}, "bufs": []}'), "twice"),
    "bad-buffer-length": (raw_frame('{"v": 1, "bufs": [-1]}'), "non-negative"),
    "prefix-disagrees": (
        raw_frame('{"v": {"$t": "bytes", "buf": 0}, "bufs": [3]}', struct.pack(">Q", 4), b"abcd"),
        "3 bytes in the header but 4",
    ),
    "deep-json": (raw_frame('{"v": ' + "[" * 10_000 + "]" * 10_000 + ', "bufs": []}'), "nested"),
    "deep-json-objects": (raw_frame('{"v": ' + '{"a":' * 10_000 + "1" + "}" * 10_000 + ', "bufs": []}'), "nested"),
    "forged-object-array": (
        raw_frame('{"v": {"$t": "nd", "dtype": "|O", "shape": [1], "buf": 0}, "bufs": [8]}', struct.pack(">Q", 8), b"\0" * 8),
        "dtype",
    ),
}


@pytest.mark.parametrize("frame, match", BAD_FRAMES.values(), ids=BAD_FRAMES.keys())
def test_bad_frames_raise_protocol_error(pair, frame, match):
    a, b = pair
    join = send_in_thread(lambda: a.sendall(frame))
    with pytest.raises(ProtocolError, match=match):
        recv_message(b, timeout=5)
    join()


def test_frame_layout(pair):
    a, b = pair
    size = send_message(a, [b"ab", np.array([1], dtype="|u1")])
    data = b.recv(1000)
    assert len(data) == size
    (header_len,) = struct.unpack(">I", data[:4])
    header = json.loads(data[4 : 4 + header_len])
    assert header == {"v": [{"$t": "bytes", "buf": 0}, {"$t": "nd", "dtype": "|u1", "shape": [1], "buf": 1}], "bufs": [2, 1]}
    assert data[4 + header_len :] == struct.pack(">Q", 2) + b"ab" + struct.pack(">Q", 1) + b"\x01"


def test_encode_result_composes_with_an_envelope(pair):
    a, b = pair
    value = (np.eye(3), [nested(MAX_DEPTH - 6)])  # depth 28: the most encode_result takes
    tree, buffers = encode_result(value)
    send_frame(a, {"status": "ok", "value": tree}, buffers)
    got = recv_message(b, timeout=5)
    assert got["status"] == "ok"
    assert_same(got["value"], value)


def test_recv_frame_returns_raw_tree_and_buffers(pair):
    a, b = pair
    send_message(a, {"x": b"abc"})
    tree, buffers = recv_frame(b, timeout=5)
    assert tree == {"x": {"$t": "bytes", "buf": 0}} and bytes(buffers[0]) == b"abc"


def test_send_frame_rejects_a_non_json_tree(pair):
    a, _ = pair
    with pytest.raises(ProtocolError, match="not plain JSON"):
        send_frame(a, {"v": math.nan}, [])


# --------------------------------------------------------------------------
# the modules themselves


@pytest.mark.parametrize("module", [codec, frames, limits, values], ids=lambda m: m.__name__)
def test_boundary_imports_only_stdlib_numpy_and_errors(module):
    source = Path(module.__file__).read_text()
    tree = ast.parse(source)
    imported = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            imported |= {alias.name.split(".")[0] for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported.add(node.module.split(".")[0] if node.module else "")
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            assert node.func.id not in {"eval", "exec", "__import__", "compile"}
    assert "pickle" not in imported and "matplotlib" not in imported
    stdlib = sys.stdlib_module_names
    assert {m for m in imported if m not in stdlib} <= {"numpy", "autograder", "__future__"}


# --------------------------------------------------------------------------
# function references ("fn" tag)


def test_callable_ref_round_trips_as_plain_data():
    ref = CallableRef("g1", "f", "numpy.sin")
    tree, buffers = encode([ref, {"k": CallableRef("7.2")}])
    assert tree[0] == {"$t": "fn", "id": "g1", "name": "f", "safe": "numpy.sin"}
    assert tree[1]["k"] == {"$t": "fn", "id": "7.2", "name": "f"}
    got = decode(tree, buffers)
    assert got == [ref, {"k": CallableRef("7.2", "f", "")}]
    assert type(got[0]) is CallableRef


def test_callables_stay_unsupported_without_a_callable_encoder():
    (node, _) = encode(lambda x: x)
    assert node["$t"] == "unsupported"


def test_callable_encoder_turns_callables_into_refs_and_never_pickles():
    seen = []

    def export(value):
        seen.append(value)
        return CallableRef(f"9.{len(seen)}", "function")

    def student_function(x):
        return x

    class Interpolant:
        def __call__(self, x):
            return x

    tree, _ = encode({"f": student_function, "g": [Interpolant(), np.sin]},
                     callable_encoder=export)
    assert tree == {"f": {"$t": "fn", "id": "9.1", "name": "function"},
                    "g": [{"$t": "fn", "id": "9.2", "name": "function"},
                          {"$t": "fn", "id": "9.3", "name": "function"}]}
    assert seen[0] is student_function
    refused, _ = encode(student_function, callable_encoder=lambda v: None)
    assert refused["$t"] == "unsupported"


@pytest.mark.parametrize("node", [
    {"$t": "fn", "id": "", "name": "f"},
    {"$t": "fn", "id": "a b", "name": "f"},
    {"$t": "fn", "id": 3, "name": "f"},
    {"$t": "fn", "id": "x" * 65, "name": "f"},
    {"$t": "fn", "id": "g1", "name": 1},
    {"$t": "fn", "id": "g1", "name": "f", "safe": "os.system"},
    {"$t": "fn", "id": "g1", "name": "f", "code": "print(1)"},
    {"$t": "fn", "id": "g1"},
])
def test_forged_function_refs_are_rejected(node):
    with pytest.raises(ProtocolError):
        decode(node)


def test_replace_refs_walks_decoded_containers_only():
    ref = CallableRef("g1")
    value = {"a": [1, (ref, 2.0)], "b": np.zeros(2)}
    out = replace_refs(value, lambda r: f"stub-{r.id}")
    assert out["a"] == [1, ("stub-g1", 2.0)] and out["b"] is value["b"]
    plain = [1, [2, 3], {"x": 4}]
    assert replace_refs(plain, lambda r: None) is plain


def test_safe_functions_are_numpy_ufuncs():
    for name in values.SAFE_FUNCTIONS:
        module, attr = name.split(".")
        assert module == "numpy" and isinstance(getattr(np, attr), np.ufunc), name
