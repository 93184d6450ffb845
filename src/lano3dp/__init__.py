"""lano3dp: language-guided, object-centric 3D diffusion policies (Lan-o3dp)."""

__version__ = "0.1.0"
