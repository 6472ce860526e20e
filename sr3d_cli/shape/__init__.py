"""Object shape models the stages share (segment weighs cuts with them, reconstruct makes its
meshes from them), fitted from a silhouette and the raw readings:
:mod:`sr3d_cli.shape.revolution_fit`, a surface of revolution standing or lying on the table, in
the object frame of :mod:`sr3d_cli.geometry.revolution`.
"""
