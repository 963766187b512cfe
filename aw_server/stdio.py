"""The stdio transport, with an answer for every malformed request.

The SDK's stdio reader drops a line it cannot decode (invalid JSON, a 5,001-digit integer,
5,000-deep nesting, an object that is no JSON-RPC message) after logging it, so a client that
sent it waits forever. Here each such line gets a JSON-RPC error reply instead: ``-32700``
(parse error) or ``-32600`` (invalid request), with the request's id when it can be read off the
line's top level, else ``null`` as JSON-RPC 2.0 prescribes.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from typing import Any

import anyio
from mcp.server.mcpserver import MCPServer
from mcp.server.stdio import stdio_server
from mcp.shared.message import SessionMessage
from mcp_types import INVALID_REQUEST, PARSE_ERROR, ErrorData, JSONRPCError
from pydantic import ValidationError

__all__ = ["error_reply", "request_id", "serve_stdio"]

MAX_ID_DIGITS = 18  # a JSON-RPC id the client can match; longer "ids" are answered with null
_WS = " \t\r\n"


def _scan_string(text: str, i: int) -> int:
    """Index just past the JSON string starting at ``text[i] == '"'`` (len(text) if unterminated)."""
    i += 1
    while i < len(text):
        c = text[i]
        if c == "\\":
            i += 2
            continue
        if c == '"':
            return i + 1
        i += 1
    return len(text)


def request_id(text: str) -> int | str | None:
    """The ``id`` member of the top-level JSON object in ``text``, found without parsing the
    whole text (which may be too deep or hold numbers too long to parse); None if there is none."""
    i = next((k for k, c in enumerate(text) if c not in _WS), len(text))
    if i >= len(text) or text[i] != "{":
        return None
    depth, i, expect_key = 0, i, False
    while i < len(text):
        c = text[i]
        if c == '"':
            end = _scan_string(text, i)
            if depth == 1 and expect_key:
                key = text[i:end]
                j = end
                while j < len(text) and text[j] in _WS:
                    j += 1
                if key == '"id"' and j < len(text) and text[j] == ":":
                    return _id_value(text, j + 1)
                expect_key = False
            i = end
            continue
        if c in "{[":
            depth += 1
            expect_key = depth == 1
        elif c in "}]":
            depth -= 1
        elif c == "," and depth == 1:
            expect_key = True
        i += 1
    return None


def _id_value(text: str, i: int) -> int | str | None:
    while i < len(text) and text[i] in _WS:
        i += 1
    if i < len(text) and text[i] == '"':
        try:
            value = json.loads(text[i : _scan_string(text, i)])
        except ValueError:
            return None
        return value if isinstance(value, str) else None
    j = i + (1 if text[i : i + 1] == "-" else 0)
    k = j
    while k < len(text) and text[k].isdigit():
        k += 1
    digits = text[j:k]
    if not digits or k - j > MAX_ID_DIGITS or (k < len(text) and text[k] in ".eE"):
        return None
    return int(text[i:k])


def error_reply(exc: Exception) -> JSONRPCError | None:
    """The reply to a line the transport could not decode (``exc`` as the SDK's reader raised it)."""
    if not isinstance(exc, ValidationError):
        return None
    errors = exc.errors()
    first: Mapping[str, Any] = errors[0] if errors else {}
    raw: Any = first.get("input")
    if first.get("type") == "json_invalid":
        detail = str(first.get("msg", "invalid JSON"))
        rid = request_id(raw) if isinstance(raw, str) else None
        return JSONRPCError(jsonrpc="2.0", id=rid, error=ErrorData(code=PARSE_ERROR, message=f"Parse error: {detail}"))
    rid = raw.get("id") if isinstance(raw, dict) else None
    if not (isinstance(rid, str) or (isinstance(rid, int) and not isinstance(rid, bool))):
        rid = None
    return JSONRPCError(
        jsonrpc="2.0",
        id=rid,
        error=ErrorData(
            code=INVALID_REQUEST, message="Invalid Request: not a JSON-RPC 2.0 request, notification or response"
        ),
    )


class _AnsweringReader:
    """The server's read stream: decoding failures are answered on ``write`` and not passed on."""

    def __init__(self, inner: Any, write: Any):
        self._inner = inner
        self._write = write

    @property
    def last_context(self):
        return getattr(self._inner, "last_context", None)

    async def receive(self) -> SessionMessage:
        while True:
            item = await self._inner.receive()
            if not isinstance(item, Exception):
                return item
            reply = error_reply(item)
            if reply is not None:
                try:
                    await self._write.send(SessionMessage(reply))
                except (anyio.ClosedResourceError, anyio.BrokenResourceError):
                    pass

    def __aiter__(self) -> _AnsweringReader:
        return self

    async def __anext__(self) -> SessionMessage:
        try:
            return await self.receive()
        except anyio.EndOfStream:
            raise StopAsyncIteration from None

    async def __aenter__(self) -> _AnsweringReader:
        return self

    async def __aexit__(self, *exc) -> None:
        await self.aclose()

    def close(self) -> None:
        self._inner.close()

    async def aclose(self) -> None:
        await self._inner.aclose()


async def _serve(server: MCPServer) -> None:
    lowlevel = server._lowlevel_server  # what MCPServer.run_stdio_async serves; mcp is pinned <3
    async with stdio_server() as (read_stream, write_stream):
        await lowlevel.run(
            _AnsweringReader(read_stream, write_stream), write_stream, lowlevel.create_initialization_options()
        )


def serve_stdio(server: MCPServer) -> None:
    """Serve ``server`` over stdin/stdout until the client closes stdin."""
    anyio.run(_serve, server)
