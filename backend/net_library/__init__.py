"""The net library the RoboGraph editor publishes into (docs/nets.md, "Publish"): every
version kept in the database, the live ones installed in the server's dispatch and sent to the
robots."""
