"""File formats: motion (BVH, ASF/AMC, npz, CSV, TRC), markers (C3D, TRC, CSV), cameras, sessions.

Submodules are imported explicitly (``from mocapkit.io.bvh import read_bvh``) so that
importing one format does not pull in the others' dependencies.
"""
