"""Command-line tools: the demo (main job), graph launcher, monitor."""
