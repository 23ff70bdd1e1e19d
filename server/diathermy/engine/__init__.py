"""The engine: a simulation session's state and the step that advances it."""
