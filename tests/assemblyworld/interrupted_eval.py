"""An eval to interrupt: ``python interrupted_eval.py SUITE RUNS LOGS`` makes one call, prints
``WAITING`` and then waits in its next model call until it is interrupted (Ctrl-C)."""

from __future__ import annotations

import signal
import sys

import anyio
from inspect_ai import eval as inspect_eval
from inspect_helpers import NONE_TASK, Script, output


async def wait_forever(messages):
    print("WAITING", flush=True)
    await anyio.sleep(3600)
    return output("text", "never")


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C as at a terminal (a background shell ignores it)
    suite, runs, logs = sys.argv[1:4]
    script = Script([lambda m: output("call", "start_episode", {}), wait_forever])
    inspect_eval(
        "assemblyworld/assemblyworld",
        model=script.model(),
        task_args={"suite": suite, "runs": runs, "tasks": NONE_TASK},
        log_dir=logs,
        display="none",
    )
