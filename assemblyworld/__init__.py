"""AssemblyWorld as an Inspect AI task: ``inspect eval assemblyworld/assemblyworld --model M``.

Install with ``pip install 'assemblyworld[inspect]'``. Inspect finds the task through the
``inspect_ai`` entry point (:mod:`assemblyworld._registry`). Top-down:

- :mod:`assemblyworld.task`: the task and its arguments;
- :mod:`assemblyworld.samples`: one sample per suite task (the task text, the reference images);
- :mod:`assemblyworld.episode`: the solver, Inspect's ReAct agent on the task's ``aw-serve``;
- :mod:`assemblyworld.runinfo`: the episode's ``run.json``, as the other runners write it;
- :mod:`assemblyworld.scorer`: the protocol's scores and the Overall metrics (eq. 3);
- :mod:`assemblyworld.suite`: the embedded synthetic suite, built on first use;
- :mod:`assemblyworld.hooks`: epochs for the recording layout, the exit status of ``inspect eval``.

``aw`` and ``aw_eval`` never import this package.
"""
