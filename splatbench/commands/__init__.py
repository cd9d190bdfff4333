"""Small CLI commands (each module defines one click command)."""
