"""VDA 5050 ground shared by the master control (backend/vda5050/) and the simulated vehicle:
the official JSON schemas, topic names, the broker's address and one MQTT session with
reconnection (docs/vda5050.md)."""
