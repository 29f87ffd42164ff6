"""Drake systems and diagram builders: keypoint sources, simulation, replays, perception, tasks
(`run_task`), the pipeline and the `demo` and `plan` commands."""
