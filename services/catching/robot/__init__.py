"""Robot data and control that run on a node: PUMA 560 kinematics, catching motion control."""

__all__: list[str] = []
