"""What the staff console needs from the server beyond the domain services: lock changes,
alerts (persisted, acknowledged), the running Petri nets and their markings, and the live
event log, all published on the hub (docs/console.md)."""
