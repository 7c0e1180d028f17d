"""``python -m building_sim``: the same as ``guidebot building-sim``."""

from building_sim.cli import building_sim

building_sim()
