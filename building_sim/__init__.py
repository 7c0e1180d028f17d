"""building_sim: the building's Modbus/TCP I/O modules, doors, elevators and buttons, simulated.

See docs/building.md. Python API: ``building_sim.simulator.BuildingSimulator``; command line:
``guidebot building-sim``.
"""
