"""LAZ files for the tests: written by laspy's lazrs back-end (an encoder
independent of gdt-tile's decoder), and taken apart or rewritten at the
byte level (the LASzip VLR, the chunks, the chunk table) to make broken
ones."""
import contextlib
import io
import pathlib
import struct

import laspy
import laspy._compression.lazrsbackend as lazrs_backend
import lazrs

LAZ_VLR_USER = b"laszip encoded"
LAZ_VLR_ID = 22204


@contextlib.contextmanager
def chunk_size(points):
    """Inside the block, laspy's lazrs writer makes chunks of `points`
    points (its own default is 50000, more than small test clouds hold):
    the chunk size is a field of the LASzip VLR the compressor is built
    from."""
    orig = lazrs_backend.LazrsPointWriter.__init__

    def init(self, dest, point_format, parallel):
        orig(self, dest, point_format, parallel)
        data = bytearray(self.vlr.record_data())
        struct.pack_into("<I", data, 12, points)
        self.vlr = lazrs.LazVlr(bytes(data))

    lazrs_backend.LazrsPointWriter.__init__ = init
    try:
        yield
    finally:
        lazrs_backend.LazrsPointWriter.__init__ = orig


def write_laz(src, out, chunk=None):
    """Writes src (a LAS path or a laspy.LasData) as LAZ at out, in chunks of
    `chunk` points (None: lazrs's default)."""
    las = laspy.read(str(src)) if isinstance(src, (str, pathlib.Path)) else src
    ctx = chunk_size(chunk) if chunk is not None else contextlib.nullcontext()
    with ctx:
        las.write(str(out), laz_backend=laspy.LazBackend.Lazrs)
    return pathlib.Path(out)


class Layout:
    """Where the parts of a LAZ file lie (byte offsets into it)."""

    def __init__(self, path):
        self.path = pathlib.Path(path)
        data = self.path.read_bytes()
        self.size = len(data)
        self.header_size = struct.unpack_from("<H", data, 94)[0]
        self.points_start = struct.unpack_from("<I", data, 96)[0]
        nvlr = struct.unpack_from("<I", data, 100)[0]
        self.format_byte = data[104]
        self.record_length = struct.unpack_from("<H", data, 105)[0]
        self.count = struct.unpack_from("<I", data, 107)[0]
        if data[25] >= 4 and self.count == 0:
            self.count = struct.unpack_from("<Q", data, 247)[0]
        self.vlr = None  # (payload offset, payload length) of the LASzip VLR
        pos = self.header_size
        for _ in range(nvlr):
            user = data[pos + 2:pos + 18].rstrip(b"\0")
            rid, n = struct.unpack_from("<HH", data, pos + 18)
            if user == LAZ_VLR_USER and rid == LAZ_VLR_ID:
                self.vlr = (pos + 54, n)
            pos += 54 + n
        assert self.vlr is not None, f"{path}: no LASzip VLR"
        self.vlr_payload = data[self.vlr[0]:self.vlr[0] + self.vlr[1]]
        self.table_offset = struct.unpack_from("<q", data, self.points_start)[0]
        src = io.BytesIO(data)
        src.seek(self.points_start)
        table = lazrs.read_chunk_table(src, lazrs.LazVlr(self.vlr_payload))
        self.chunks = []  # (start, bytes, points)
        start = self.points_start + 8
        for points, nbytes in table:
            self.chunks.append((start, nbytes, points))
            start += nbytes
        self.data_end = start

    def boundaries(self):
        """Offsets where chunks start, and the end of the last one."""
        return [c[0] for c in self.chunks] + [self.data_end]


def write_table(path, entries, payload):
    """Replaces the chunk table at the end of the LAZ file at path by one
    holding entries [(points, bytes), ...] (payload: the LASzip VLR's)."""
    lay = Layout(path)
    data = bytearray(path.read_bytes()[:lay.table_offset])
    out = io.BytesIO()
    lazrs.write_chunk_table(out, entries, lazrs.LazVlr(payload))
    path.write_bytes(bytes(data) + out.getvalue())
