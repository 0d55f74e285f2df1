"""Generated worlds: KINDS maps a kind to its generate(rng) -> world file mapping (docs/worlds.md)."""
from . import maze

KINDS = {"maze": maze.generate}
