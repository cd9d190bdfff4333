"""A slow, float64, pure-NumPy reference renderer for 3D Gaussian Splatting."""
