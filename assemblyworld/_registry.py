"""The module Inspect's ``inspect_ai`` entry point loads: it registers ``assemblyworld/assemblyworld``
and the hooks."""

from assemblyworld.hooks import AssemblyWorldHooks
from assemblyworld.task import assemblyworld

__all__ = ["AssemblyWorldHooks", "assemblyworld"]
