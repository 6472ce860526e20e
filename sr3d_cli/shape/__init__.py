"""Object shape models shared by segment, reconstruct and align, fitted from a silhouette and
the raw readings: :mod:`sr3d_cli.shape.revolution_fit` (a surface of revolution standing or
lying on the table). The object frame they are written in is :mod:`sr3d_cli.geometry.revolution`'s.
"""
