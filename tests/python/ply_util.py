"""Reading a gdt-tile PLY whole into numpy, for tests on small meshes."""
import pathlib

import numpy as np

FACE_RECORD = np.dtype([("n", "u1"), ("v", "<i4", 3)])


def read_ply(path):
    """(header text, V x 3 float64 vertices, F face records (n, v))."""
    data = pathlib.Path(path).read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    nv = int(header.split("element vertex")[1].split()[0])
    nf = int(header.split("element face")[1].split()[0])
    verts = np.frombuffer(data, dtype="<f8", count=3 * nv, offset=end).reshape(nv, 3)
    faces = np.frombuffer(data, dtype=FACE_RECORD, count=nf, offset=end + 24 * nv)
    assert (faces["n"] == 3).all(), f"{path}: a face that is no triangle"
    return header, verts, faces


def read_ply_triangles(path):
    """(header text, vertices, F x 3 int64 vertex indices)."""
    header, verts, faces = read_ply(path)
    return header, verts, faces["v"].astype(np.int64)
