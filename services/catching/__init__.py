"""The catching testbed's node side (paper section 6, "Visual Servoing and Catching", Fig. 1)."""

__all__: list[str] = []
