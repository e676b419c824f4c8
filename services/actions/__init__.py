"""Primitive actions hosted by nodes, placed by services.toml (``impl = "module:object"``)."""

__all__: list[str] = []
