"""sr3d: training-free depth repair for transparent and specular objects from one RGB-D frame."""

__version__ = "0.1.0"
