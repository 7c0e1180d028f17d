"""What-if planning: a venue's day of visitors played over simulated fleets (docs/planning.md)."""
