"""The simulated catching testbed (paper section 6, Fig. 1)."""

__all__: list[str] = []
