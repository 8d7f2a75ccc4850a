"""Small helpers for messages people read."""


def plural(count: int, noun: str) -> str:
    """'1 command', '3 commands', '0 subscribers'."""
    return f"{count} {noun}" if count == 1 else f"{count} {noun}s"
