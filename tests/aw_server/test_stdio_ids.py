"""aw_server.stdio.request_id: the top-level id of a line too deep or too long to parse."""

from __future__ import annotations

import pytest

from aw_server.stdio import request_id


@pytest.mark.parametrize(
    "line, expected",
    [
        ('{"jsonrpc":"2.0","id":7,"method":"x"}', 7),
        ('{"jsonrpc":"2.0","id":-3}', -3),
        ('{"id" : "a\\"b", "x": 1}', 'a"b'),
        ('{"params":{"id":"inner"},"id":9}', 9),  # a nested "id" is not the request's
        ('{"params":{"arguments":{"id":"p01"}}', None),
        ('{"x":"\\"id\\":5"}', None),  # inside a string
        ('{"x":' + "[" * 5000 + "]" * 5000 + ',"id":4}', 4),
        ('{"id":' + "1" * 40 + "}", None),  # no usable id: answered with null
        ('{"id":1.5}', None),
        ('{"id":null}', None),
        ("[1,2]", None),
        ("", None),
        ('{"id":"unterminated', None),
    ],
)
def test_request_id(line, expected):
    assert request_id(line) == expected
