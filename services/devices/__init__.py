"""Device links a node needs on real hardware: the CAN master of CiA 402 drives, the frame grabber."""

__all__: list[str] = []
