"""The server's site services: the live site and its reloads, drafts, roll-out, diff and CLI.

The site model itself (schema, YAML, validation, texts, graph) lives in guidebot.site, which
every process may import.
"""
