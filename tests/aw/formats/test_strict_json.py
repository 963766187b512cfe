"""The one JSON reader (aw.formats.strict_json): the rule and the limits, each refusal an exact
one-line message; duplicate keys found by counting, checked against Python's json on random
documents; files and lines read in bounded pieces."""

from __future__ import annotations

import json
import os
import re
import threading

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aw.formats import FormatError
from aw.formats.io import last_line, read_tail
from aw.formats.strict_json import (
    LIMITS,
    JsonError,
    JsonLimits,
    iter_lines,
    parse_json,
    read_json,
    read_json_lines,
    read_json_object,
)
from tests.aw.formats.hostile_json import FRAGMENTS, IDS, inject

DEEP_65 = b"[" * 65 + b"]" * 65


@pytest.mark.parametrize(
    "data, limits, message",
    [
        (DEEP_65, LIMITS, "JSON nested deeper than 64 levels"),
        (b'{"a": ' * 3000 + b"1" + b"}" * 3000, LIMITS, "JSON nested deeper than 64 levels"),
        (b"[" * 100_000 + b"]" * 100_000, LIMITS, "JSON nested deeper than 64 levels"),
        (b"[[[]]]", JsonLimits(max_depth=2), "JSON nested deeper than 2 levels"),
        (
            b"1" + b"0" * 400,
            LIMITS,
            "not valid JSON: a number beyond the range of a double (+-1.8e308) at char 0",
        ),
        (b"[0, -1e400]", LIMITS, "not valid JSON: a number beyond the range of a double (+-1.8e308) at char 4"),
        (b'{"a": NaN}', LIMITS, "not valid JSON: NaN at char 6 (NaN and Infinity are not JSON numbers)"),
        (b"[-Infinity]", LIMITS, "not valid JSON: Infinity at char 2 (NaN and Infinity are not JSON numbers)"),
        (b'{"a": 1, "a": 2}', LIMITS, "duplicate key 'a'"),
        (b'{"x": [{"b": 1}, {"b": 2, "c": {}, "b": 3}]}', LIMITS, "duplicate key 'b'"),
        (b'{"a\\u003a": 1, "a:": 2}', LIMITS, "duplicate key 'a:'"),
        (b'{"k": 1, "k": 2, "x": "\\u003a"}', LIMITS, "duplicate key 'k'"),  # an escaped colon kept
        (b'{"' + b"k" * 50 + b'": 1, "' + b"k" * 50 + b'": 1}', LIMITS, f"duplicate key {'k' * 37 + '...'!r}"),
        (b'["ok", "\xff"]', LIMITS, "not valid JSON: not UTF-8 text (byte 8)"),
        (b'"\\ud800"', LIMITS, "not valid JSON (no low surrogate in string: line 1 column 2 (char 1))"),
        (b"", LIMITS, "not valid JSON (Input is a zero-length, empty document: line 1 column 1 (char 0))"),
        (b"{} x", LIMITS, "not valid JSON (unexpected content after document: line 1 column 4 (char 3))"),
        (
            b'{"category": "' + b"x" * 11 + b'"}',
            JsonLimits(max_string_chars=10),
            "'category': a string of 11 characters, over the limit of 10",
        ),
        (b'["' + b"x" * 11 + b'"]', JsonLimits(max_string_chars=10), "a string of 11 characters, over the limit of 10"),
        (
            b'{"' + b"x" * 11 + b'": 1}',
            JsonLimits(max_string_chars=10),
            "a string of 11 characters, over the limit of 10",
        ),
        (
            b"[" + b"0," * 10 + b"0]",
            JsonLimits(max_document_bytes=10),
            "23 bytes, over the limit of 10 for a JSON document",
        ),
    ],
)
def test_a_refused_document_is_named_in_one_line(data, limits, message):
    with pytest.raises(JsonError) as info:
        parse_json(data, limits)
    assert str(info.value) == message


@pytest.mark.parametrize("fragment", FRAGMENTS, ids=IDS)
def test_every_hostile_fragment_is_refused_anywhere_in_a_document(fragment):
    doc = {"format": "x", "poses": {"p01": [0, 0, 0, 1, 0, 0, 0]}}
    for path in (("format",), ("poses", "p01"), ("poses", "p01", 2)):
        with pytest.raises(JsonError) as info:
            parse_json(inject(doc, path, fragment).encode())
        assert fragment.message in str(info.value)


def test_what_the_rule_accepts():
    assert parse_json(b'{"a:b": "c:d", "e": ["::", {"f:": ":"}]}') == {"a:b": "c:d", "e": ["::", {"f:": ":"}]}
    assert parse_json(b'{"a\\u003a": 1, "b\\u003A": 2}') == {"a:": 1, "b:": 2}  # escaped colons, no duplicate
    assert parse_json(b"[" * 64 + b"]" * 64) is not None and parse_json(DEEP_65, JsonLimits(max_depth=65))
    assert parse_json(b"[18446744073709551615, -9223372036854775808, 1e300, 5e-324]") == [
        2**64 - 1,
        -(2**63),
        1e300,
        5e-324,
    ]
    assert parse_json(b'"x"') == "x" and parse_json(b"3") == 3 and parse_json(b"null") is None
    assert parse_json('{"\u00e9": "\U0001f600"}') == {"\u00e9": "\U0001f600"}  # text as well as bytes
    with pytest.raises(ValueError, match="max_depth must be within 1..254, got 300"):
        JsonLimits(max_depth=300)


_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**63 - 1)
    | st.floats(allow_nan=False, allow_infinity=False)
    | st.text(alphabet=st.sampled_from('ab:"\\\u00e9\U0001f600'), max_size=6),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(alphabet="ab:", max_size=3), inner, max_size=3),
    max_leaves=12,
)


@settings(max_examples=150, deadline=None)
@given(_values, st.booleans())
def test_every_json_document_reads_back_as_pythons_json_reads_it(value, ascii_only):
    text = json.dumps(value, ensure_ascii=ascii_only)
    assert parse_json(text.encode()) == json.loads(text) == value


@settings(max_examples=150, deadline=None)
@given(st.dictionaries(st.text(alphabet="ab:\u00e9", max_size=3), _values, min_size=1, max_size=4), _values, st.data())
def test_a_duplicate_key_is_always_found(doc, again, data):
    key = data.draw(st.sampled_from(sorted(doc)))
    text = json.dumps({"outer": doc})[:-2] + f", {json.dumps(key)}: {json.dumps(again)}" + "}}"
    if data.draw(st.booleans()):  # colons inside strings written as escapes (no string holds ": ")
        text = re.sub(r":(?! )", r"\\u003a", text)
    with pytest.raises(JsonError) as info:
        parse_json(text.encode())
    assert str(info.value) == f"duplicate key {key!r}"


def test_files_are_named_and_refused_by_size_before_they_are_read(tmp_path):
    def problem(call, path) -> str:
        with pytest.raises(FormatError) as info:
            call(path)
        assert info.value.path == path
        return info.value.problem

    assert problem(read_json, tmp_path / "missing.json") == "file not found"
    assert problem(read_json, tmp_path) == "is a directory, not a file"
    sparse = tmp_path / "big.json"
    with open(sparse, "wb") as fh:
        fh.truncate(LIMITS.max_document_bytes + 1)
    assert problem(read_json, sparse) == "67108865 bytes, over the limit of 67108864 for a JSON file"
    (tmp_path / "list.json").write_text("[1]")
    assert problem(read_json_object, tmp_path / "list.json") == "expected a JSON object, got an array"
    (tmp_path / "deep.json").write_bytes(DEEP_65)
    assert problem(read_json, tmp_path / "deep.json") == "JSON nested deeper than 64 levels"


def test_json_lines_are_read_one_bounded_line_at_a_time(tmp_path):
    path = tmp_path / "rows.jsonl"
    path.write_bytes(b'{"a": 1}\n\n' + b"[" + b"0," * 20 + b"0]\n" + b'{"b": 2}\n{"c": NaN}\n')
    limits = JsonLimits(max_document_bytes=16)
    rows = read_json_lines(path, limits=limits)
    assert next(rows) == (1, {"a": 1})
    with pytest.raises(FormatError) as info:
        next(rows)
    assert info.value.problem == "line 3: over the limit of 16 bytes for one line"
    with pytest.raises(FormatError) as info:
        list(read_json_lines(path))
    assert info.value.problem == "line 5: not valid JSON: NaN at char 6 (NaN and Infinity are not JSON numbers)"
    with open(path, "rb") as fh:
        assert [(n, line is None) for n, line in iter_lines(fh, 16)] == [
            (1, False),
            (2, False),
            (3, True),  # skipped unread; the next line is whole
            (4, False),
            (5, False),
        ]


def test_a_child_log_is_read_from_its_tail(tmp_path):
    log = tmp_path / "refiner.log"
    with open(log, "wb") as fh:
        fh.write(b"starting\n")
        fh.seek(300 << 20)  # 300 MiB of NUL bytes (sparse), then the verdict
        fh.write(b"\x1b[31mrefiner x: no answer\x1b[0m\n\n")
    assert len(read_tail(log)) == 64 << 10
    assert last_line(log) == "[31mrefiner x: no answer[0m"
    assert last_line(tmp_path / "missing.log") == "" and read_tail(tmp_path / "missing.log") == ""


def test_a_pipe_is_read_no_further_than_the_limit(tmp_path):
    fifo = tmp_path / "pipe.json"
    os.mkfifo(fifo)

    def write() -> None:  # more than the limit, then it closes
        with open(fifo, "wb") as fh:
            fh.write(b"[" + b"0," * 100)

    writer = threading.Thread(target=write)
    writer.start()
    with pytest.raises(FormatError) as info:
        read_json(fifo, limits=JsonLimits(max_document_bytes=64))
    writer.join()
    assert info.value.problem == "over the limit of 64 bytes for a JSON file"
