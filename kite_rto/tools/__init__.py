"""Command-line tools: the main job (demo), the process launcher, monitor, echo, MCAP recording, reports, the
fault relay and table. The nodes never import them (docs/architecture.md)."""

__all__: list[str] = []
