"""The fire alarm on the server: state, holds, REST (docs/emergency.md)."""
