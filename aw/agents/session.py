"""The agents' only window on the environment: MCP tool calls over a connected SDK ``Client``.

:class:`ToolSession` counts calls per tool, times each one out (a server that stops answering is
*hung*, not slow), and keeps a small progress file up to date so that the supervising runner can
tell, when it has to kill an episode, whether a call was in flight (hung) or the agent was
simply still working (timeout).
"""

from __future__ import annotations

import base64
import json
import os
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from mcp import Client
from mcp.shared.exceptions import MCPError

REQUEST_TIMEOUT_CODE = -32001


class ServerHung(RuntimeError):
    """The server did not answer a request within the per-call limit."""


class ToolFailed(RuntimeError):
    """A tool returned an MCP tool error (``is_error``); the scene is unchanged."""

    def __init__(self, tool: str, message: str):
        super().__init__(f"{tool}: {message}")
        self.tool = tool
        self.message = message


@dataclass
class ToolResult:
    """One tool call's outcome. ``data``: structured content (or the JSON text parsed),
    ``images``: PNG bytes of any image content, ``text``: concatenated text content."""

    tool: str
    ok: bool
    data: Any = None
    text: str = ""
    images: list[bytes] = field(default_factory=list)


class ToolSession:
    """Tool calls with per-call limits, counting and progress reporting.

    ``progress_path``: JSON file rewritten (atomically) before and after every call:
    ``{"calls": n, "in_flight": tool|null, "since": unix_time}``.
    """

    def __init__(self, client: Client, call_timeout: float = 120.0, progress_path: Path | None = None):
        self.client = client
        self.call_timeout = call_timeout
        self.progress_path = progress_path
        self.counts: Counter[str] = Counter()
        self.errors: Counter[str] = Counter()
        self.images_seen = 0
        self._write_progress(None)

    @property
    def n_calls(self) -> int:
        return sum(self.counts.values())

    def _write_progress(self, in_flight: str | None) -> None:
        if self.progress_path is None:
            return
        tmp = self.progress_path.with_suffix(".tmp")
        tmp.write_text(
            json.dumps(
                {"calls": self.n_calls, "in_flight": in_flight, "since": time.time(), "counts": dict(self.counts)}
            )
        )
        os.replace(tmp, self.progress_path)

    async def _request(self, label: str, coro_fn):
        self._write_progress(label)
        try:
            return await coro_fn()
        except MCPError as exc:
            if exc.error.code == REQUEST_TIMEOUT_CODE:
                raise ServerHung(f"the server did not answer {label} within {self.call_timeout:g} s") from None
            raise
        finally:
            self._write_progress(None)

    async def call(self, tool: str, args: dict[str, Any] | None = None, check: bool = True) -> ToolResult:
        """Call ``tool``. With ``check`` a tool error raises :class:`ToolFailed`; otherwise it is
        returned as ``ok=False`` (agents that probe limits use that)."""
        args = {k: v for k, v in (args or {}).items() if v is not None}
        self.counts[tool] += 1
        res = await self._request(
            tool, lambda: self.client.call_tool(tool, args, read_timeout_seconds=self.call_timeout)
        )
        texts, images = [], []
        for block in res.content:
            kind = getattr(block, "type", None)
            if kind == "text":
                texts.append(block.text)
            elif kind == "image":
                images.append(base64.b64decode(block.data))
        self.images_seen += len(images)
        text = "\n".join(texts)
        data = res.structured_content
        if data is None and text:
            try:
                data = json.loads(text)
            except ValueError:
                data = None
        # MCPServer wraps non-object return values as {"result": value}.
        if isinstance(data, dict) and set(data) == {"result"}:
            data = data["result"]
        out = ToolResult(tool=tool, ok=not res.is_error, data=data, text=text, images=images)
        if res.is_error:
            self.errors[tool] += 1
            if check:
                raise ToolFailed(tool, text or "tool error")
        return out

    async def get_prompt(self, name: str, arguments: dict[str, str] | None = None) -> str:
        """Text of an MCP prompt (the task instructions)."""
        self.counts["prompts/get"] += 1
        res = await self._request("prompts/get", lambda: self.client.get_prompt(name, arguments or {}))
        parts = []
        for msg in res.messages:
            content = msg.content
            if getattr(content, "type", None) == "text":
                parts.append(content.text)
        return "\n".join(parts)

    async def list_prompts(self) -> list[str]:
        self.counts["prompts/list"] += 1
        res = await self._request("prompts/list", lambda: self.client.list_prompts())
        return [p.name for p in res.prompts]

    async def list_tools(self) -> list[str]:
        self.counts["tools/list"] += 1
        res = await self._request("tools/list", lambda: self.client.list_tools())
        return [t.name for t in res.tools]
