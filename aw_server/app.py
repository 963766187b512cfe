"""The MCP adapter: environment tools, the task prompt and the reference images over MCP.

Thin by design: every tool call goes to :meth:`aw.episode.Episode.call`, which executes and
records it; this module only validates arguments against the closed schemas (recording
rejected calls too), and turns results into MCP content and errors into ``ToolError``.
"""

from __future__ import annotations

from typing import Any, Literal

import anyio.to_thread
from mcp.server.mcpserver import Image, MCPServer
from mcp.server.mcpserver.exceptions import ResourceError, ToolError
from mcp.server.mcpserver.prompts.base import Prompt, UserMessage
from mcp.server.mcpserver.resources import FunctionResource
from mcp.server.mcpserver.tools import Tool
from mcp.server.mcpserver.utilities.func_metadata import FuncMetadata
from mcp_types import TextContent, ToolAnnotations
from pydantic import ValidationError

from aw.episode import Capture, Episode, EpisodeError
from aw.formats import Task
from aw_server.tools import CONVENTIONS_TEXT, TOOL_SPECS, ToolSpec, describe_validation_error, input_schema

SERVER_NAME = "assemblyworld"
PROMPT_NAME = "assembly_task"
REFERENCE_URI = "aw://task/references/{index:02d}"
PROMPT_URI = "aw://task/prompt"
_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp", ".gif": "image/gif"}

INSTRUCTIONS = (
    "AssemblyWorld: assemble rigid parts in a 3D scene. " + CONVENTIONS_TEXT + " Call start_episode first, "
    "observe with capture_scene (move_camera changes the view), edit with translate_objects, rotate_objects "
    "and set_object_pose, and group parts with group_objects. Pose edits return status only."
)


def _annotations(spec: ToolSpec) -> ToolAnnotations:
    read_only = spec.kind in ("query", "capture")
    return ToolAnnotations(
        title=spec.name.replace("_", " "),
        read_only_hint=read_only,
        destructive_hint=False if not read_only else None,
        idempotent_hint=True if spec.kind in ("query", "capture", "control") else False,
        open_world_hint=False,
    )


class ExactArgs(FuncMetadata):
    """Argument validation against the published schema only. The SDK's default first decodes any
    string argument that looks like JSON (for clients that send arrays as strings), which accepts
    inputs the schema refuses and breaks valid strings: a group named "null" lost its name."""

    def pre_parse_json(self, data: dict[str, Any]) -> dict[str, Any]:
        return dict(data)


class EpisodeTool(Tool):
    """A tool whose arguments are checked against its closed model before anything runs, so that
    schema-level rejections are recorded in the trajectory like every other call."""

    spec: Any
    episode: Any

    async def run(self, arguments: dict[str, Any], context: Any, convert_result: bool = False) -> Any:
        try:
            self.fn_metadata.validate_arguments(arguments)
        except ValidationError as exc:
            msg = describe_validation_error(self.spec, exc)
            msg = await anyio.to_thread.run_sync(self.episode.reject, self.name, arguments, msg)
            raise ToolError(f"Error executing tool {self.name}: {msg}") from None
        return await super().run(arguments, context, convert_result)


def _make_tool(spec: ToolSpec, episode: Episode) -> EpisodeTool:
    def invoke(**kwargs: Any) -> Any:
        try:
            result = episode.call(spec.name, kwargs)
        except EpisodeError as exc:
            raise ToolError(str(exc)) from None
        if isinstance(result, Capture):
            cam = result.camera
            note = (
                f"{result.width}x{result.height} view; camera yaw {cam['yaw']:.1f}, pitch {cam['pitch']:.1f}, "
                f"distance {cam['distance']:.3g}, look-at {[round(v, 4) for v in cam['target']]}"
            )
            return [Image(data=result.png, format="png"), TextContent(type="text", text=note)]
        return result

    structured = spec.kind != "capture"
    meta = ExactArgs(arg_model=spec.args, output_model=dict[str, Any] if structured else None)
    return EpisodeTool(
        fn=invoke,
        name=spec.name,
        title=spec.name.replace("_", " "),
        description=spec.description,
        parameters=input_schema(spec),
        fn_metadata=meta,
        is_async=False,
        context_kwarg=None,
        annotations=_annotations(spec),
        spec=spec,
        episode=episode,
    )


def _reference_resources(task: Task) -> list[FunctionResource]:
    out = []
    paths = task.reference_paths()
    for i, path in enumerate(paths, start=1):
        mime = _MIME.get(path.suffix.lower(), "application/octet-stream")

        def read(path=path, i=i) -> bytes:
            try:
                return path.read_bytes()
            except OSError:
                raise ResourceError(f"reference image {i} cannot be read") from None

        out.append(
            FunctionResource(
                uri=REFERENCE_URI.format(index=i),
                name=f"reference-{i:02d}",
                title=f"Reference image {i} of {len(paths)}",
                description=f"Reference image {i} of {len(paths)} ({task.condition} condition), in reading order.",
                mime_type=mime,
                fn=read,
            )
        )
    return out


def _prompt(task: Task) -> Prompt:
    def render() -> list[UserMessage]:
        messages = [UserMessage(task.prompt)]
        for path in task.reference_paths():
            fmt = _MIME.get(path.suffix.lower(), "image/png").split("/")[1]
            messages.append(UserMessage(Image(data=path.read_bytes(), format=fmt)))
        return messages

    n = len(task.references)
    return Prompt.from_function(
        render,
        name=PROMPT_NAME,
        title="AssemblyWorld task",
        description="The task text" + (f", with the {n} reference image(s) attached in order." if n else "."),
    )


# The server's log levels (aw-serve --log-level offers the first four).
LogLevel = Literal["DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"]


def build_server(episode: Episode, *, log_level: LogLevel = "WARNING") -> MCPServer:
    """An ``MCPServer`` exposing ``episode``'s tools, its task prompt and its reference images."""
    task = episode.task
    tools: list[Tool] = [_make_tool(spec, episode) for spec in TOOL_SPECS]
    resources = _reference_resources(task)
    prompt_text = FunctionResource(
        uri=PROMPT_URI,
        name="task-prompt",
        title="AssemblyWorld task text",
        description="The task text given to the agent.",
        mime_type="text/plain",
        fn=lambda: task.prompt,
    )
    server = MCPServer(
        SERVER_NAME,
        title="AssemblyWorld",
        instructions=INSTRUCTIONS,
        tools=tools,
        resources=[prompt_text, *resources],
        log_level=log_level,
    )
    server.add_prompt(_prompt(task))
    return server
