"""Reports for the people who run a venue: figures of a day, a week or any range, folded from
the event log into hourly rollups (docs/reports.md)."""
