"""Staff told where they are: alerts forwarded by e-mail and signed webhooks (docs/server.md,
"Notifications"; the console's Notifications view, docs/console.md)."""
