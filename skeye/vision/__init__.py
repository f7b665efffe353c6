"""Landing-pad vision: the concentric-ring pad, its detector, height and offset estimation."""
