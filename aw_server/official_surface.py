"""``aw-serve --surface official``: the tools an agent sees in the official benchmark.

The official runner gives its agent four MCP tools (assembly-world-bench
``experiments/transport.py``): ``list_pages``, ``list_webmcp_tools`` and ``execute_webmcp_tool``
of chrome-devtools-mcp 1.8.0, and its own ``read_manual_page``. The scene tools are page (WebMCP)
tools reached through ``execute_webmcp_tool``; here they are :class:`aw.webmcp.WebMcpPage` over
the recorded episode, and this module only reproduces the wire forms:

- ``list_pages`` -> text ``## Pages`` then ``<id>: <title> (<url>) [selected]``;
- ``list_webmcp_tools {pageId}`` -> text: a JSON list of ``{name, description, inputSchema,
  annotations}`` (assembly-world-bench ``experiments/browser.py``);
- ``execute_webmcp_tool {pageId, toolName, input}`` (``input`` a JSON string encoding an object)
  -> text ``{"status", "output", "errorText"}``; ``output`` is the tool's result as a JSON string,
  and a capture's image is attached as MCP image content, its data replaced in the text by a note
  (``experiments/transport.py``);
- ``read_manual_page {page}`` -> the task's reference page ``page`` (1-based) as MCP image content.

A bad meta-call (wrong page, a tool the page does not register, input that is not a JSON object,
a missing or extra argument) is an MCP tool error naming the argument; a bad page-tool call is a
completed call whose output is the official ``{"error", "code"}`` object, as on the official page.
"""

from __future__ import annotations

import base64
import json
import logging
from collections.abc import Callable
from typing import Any

import anyio.to_thread
from mcp.server.mcpserver import MCPServer
from mcp.server.mcpserver.tools import Tool
from mcp.server.mcpserver.utilities.func_metadata import ArgModelBase, FuncMetadata
from mcp_types import CallToolResult, ImageContent, TextContent, ToolAnnotations
from PIL import Image as PILImage

from aw.episode import Episode
from aw.webmcp import BadInput, NotRegistered, WebMcpPage, check_arguments, parse_tool_input, short_repr
from aw_server.app import LogLevel
from aw_server.tools import CONVENTIONS_TEXT

log = logging.getLogger(__name__)

SERVER_NAME = "assembly-browser"
PAGE_ID = 1
PAGE_TITLE = "AssemblyWorld episode"
IMAGE_NOTE = "Image attached as MCP image content."

_PAGE_ID = {"type": "number", "description": "The page's id, as list_pages shows it."}
META_SCHEMAS: dict[str, dict] = {
    "list_pages": {"type": "object", "properties": {}, "additionalProperties": False},
    "list_webmcp_tools": {
        "type": "object",
        "properties": {"pageId": _PAGE_ID},
        "required": ["pageId"],
        "additionalProperties": False,
    },
    "execute_webmcp_tool": {
        "type": "object",
        "properties": {
            "pageId": _PAGE_ID,
            "toolName": {"type": "string", "description": "Name of the page tool to run."},
            "input": {
                "type": "string",
                "description": 'The tool\'s arguments: a JSON object encoded as a string (default "{}").',
            },
        },
        "required": ["pageId", "toolName"],
        "additionalProperties": False,
    },
    "read_manual_page": {
        "type": "object",
        "properties": {"page": {"type": "integer", "minimum": 1}},
        "required": ["page"],
        "additionalProperties": False,
    },
}
DESCRIPTIONS = {
    "list_pages": "List the browser pages: the loaded episode page and its id.",
    "list_webmcp_tools": "List the WebMCP tools of a page: name, description, input schema, annotations.",
    "execute_webmcp_tool": "Run one WebMCP tool of a page. input is the JSON-encoded argument object; the "
    "reply is JSON {status, output, errorText} with the tool's JSON result in output.",
    "read_manual_page": "Read one supplied reference page (1-based) as an image.",
}

INSTRUCTIONS = (
    "AssemblyWorld, official tool surface: assemble rigid parts in a 3D scene. Call list_pages for the episode "
    "page id, list_webmcp_tools for its tools, and run them with execute_webmcp_tool (input is a JSON string). "
    "Reference pages, if any, can be reread with read_manual_page. " + CONVENTIONS_TEXT
)


def _text(text: str, *, error: bool = False) -> CallToolResult:
    return CallToolResult(content=[TextContent(type="text", text=text)], is_error=error)


class _RawArgs(ArgModelBase):
    """Placeholder model: the meta-tools check their raw arguments themselves (``check_arguments``)."""


class _MetaTool(Tool):
    """A tool that takes its raw arguments and returns a finished ``CallToolResult``."""

    handler: Any
    episode: Any

    async def run(self, arguments: dict[str, Any], context: Any, convert_result: bool = False) -> Any:
        return await anyio.to_thread.run_sync(self._run, dict(arguments or {}))

    def _run(self, arguments: dict[str, Any]) -> CallToolResult:
        try:
            return self.handler(arguments)
        except Exception as exc:  # a bug: answer in one line, record the failure, keep serving
            log.error("internal error in %s: %s: %s", self.name, type(exc).__name__, exc)
            message = f"{self.name} failed with an internal error"
            return _text(self.episode.reject(self.name, arguments, message), error=True)


def _tool(name: str, handler: Callable[[dict], CallToolResult], read_only: bool, episode: Episode) -> _MetaTool:
    return _MetaTool(
        fn=handler,
        name=name,
        title=name.replace("_", " "),
        description=DESCRIPTIONS[name],
        parameters=META_SCHEMAS[name],
        fn_metadata=FuncMetadata(arg_model=_RawArgs),
        is_async=False,
        context_kwarg=None,
        annotations=ToolAnnotations(read_only_hint=read_only, open_world_hint=False),
        handler=handler,
        episode=episode,
    )


class OfficialSurface:
    """The four agent-facing tools over one episode's :class:`WebMcpPage`."""

    def __init__(self, episode: Episode):
        self.episode = episode
        self.page = WebMcpPage(episode)
        self.url = f"aw://episode/{episode.task.task_id}"
        self.references = episode.task.reference_paths()

    def _problems(self, name: str, args: dict) -> str | None:
        problems = check_arguments(META_SCHEMAS[name], args)
        if not problems and "pageId" in META_SCHEMAS[name]["properties"] and args["pageId"] != PAGE_ID:
            problems = [
                f"pageId {short_repr(args['pageId'])} is not the episode page; list_pages shows it as {PAGE_ID}"
            ]
        return f"Invalid {name} arguments: " + "; ".join(problems) + "." if problems else None

    def list_pages(self, args: dict) -> CallToolResult:
        if err := self._problems("list_pages", args):
            return _text(err, error=True)
        return _text(f"## Pages\n{PAGE_ID}: {PAGE_TITLE} ({self.url}) [selected]")

    def list_webmcp_tools(self, args: dict) -> CallToolResult:
        if err := self._problems("list_webmcp_tools", args):
            return _text(err, error=True)
        return _text(json.dumps(self.page.definitions()))

    def execute_webmcp_tool(self, args: dict) -> CallToolResult:
        err = self._problems("execute_webmcp_tool", args)
        if err is None:
            try:
                reply = self.page.execute(args["toolName"], parse_tool_input(args.get("input", "{}")))
            except (BadInput, NotRegistered) as exc:
                err = str(exc)
        if err is not None:
            return _text(self.episode.reject("execute_webmcp_tool", args, err), error=True)
        output = json.dumps(reply.output, separators=(",", ":"))
        if reply.png is None:
            return _text(json.dumps({"status": "Completed", "output": output, "errorText": None}))
        # The official transport replaces the inline image by a note and attaches it as MCP image content.
        shown = {**reply.output, "content": [{"type": "text", "text": IMAGE_NOTE}]}
        text = json.dumps({"status": "Completed", "output": json.dumps(shown), "errorText": None})
        image = ImageContent(type="image", data=base64.b64encode(reply.png).decode("ascii"), mime_type="image/png")
        return CallToolResult(content=[TextContent(type="text", text=text), image])

    def read_manual_page(self, args: dict) -> CallToolResult:
        if err := self._problems("read_manual_page", args):
            return _text(err, error=True)
        n, page = len(self.references), args["page"]
        if page > n:
            have = f"{n} reference page{'s' if n != 1 else ''} (1..{n})" if n else "no reference pages"
            return _text(
                f"Invalid read_manual_page arguments: page {page} is out of range; this task has {have}.", error=True
            )
        path = self.references[page - 1]
        try:
            data = path.read_bytes()
            with PILImage.open(path) as picture:
                mime = PILImage.MIME[picture.format or ""]  # no format: KeyError, refused below
        except (OSError, KeyError):
            return _text(f"reference page {page} cannot be read", error=True)
        return CallToolResult(
            content=[ImageContent(type="image", data=base64.b64encode(data).decode("ascii"), mime_type=mime)]
        )

    def tools(self) -> list[Tool]:
        return [
            _tool("list_pages", self.list_pages, True, self.episode),
            _tool("list_webmcp_tools", self.list_webmcp_tools, True, self.episode),
            _tool("execute_webmcp_tool", self.execute_webmcp_tool, False, self.episode),
            _tool("read_manual_page", self.read_manual_page, True, self.episode),
        ]


def build_official_server(episode: Episode, *, log_level: LogLevel = "WARNING") -> MCPServer:
    """An ``MCPServer`` with the official agent-facing tools over ``episode``."""
    surface = OfficialSurface(episode)
    return MCPServer(
        SERVER_NAME,
        title="AssemblyWorld (official surface)",
        instructions=INSTRUCTIONS,
        tools=surface.tools(),
        log_level=log_level,
    )
