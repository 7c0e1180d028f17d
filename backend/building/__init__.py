"""The BuildingInterface: the central server's link to the building's Modbus/TCP I/O modules.

See docs/building.md. Modules: config (site checks), _modbus (the pymodbus adapter), filter,
poller, interface, component (server component), routes (REST view).
"""
